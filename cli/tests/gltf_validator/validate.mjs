// Runs the Khronos glTF validator on each file named and prints one JSON line per file:
// {"file", "errors", "warnings", "infos", "hints", "issues": [the errors and warnings]}.
// Exits 1 when a file has errors. Used by cli/tests/gltf_output.rs; `npm ci` here installs the
// validator (scripts/test.sh does).
//
// Usage: node cli/tests/gltf_validator/validate.mjs FILE.glb|FILE.gltf...

import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';

const validator = createRequire(import.meta.url)('gltf-validator');

let failed = false;
for (const file of process.argv.slice(2)) {
  // maxIssues 0: report every issue, so the counts are complete.
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), { maxIssues: 0 });
  const i = report.issues;
  // Severity 0 is an error, 1 a warning.
  const issues = i.messages
    .filter((m) => m.severity <= 1)
    .slice(0, 20)
    .map((m) => `${m.code} ${m.pointer ?? ''} ${m.message}`);
  console.log(JSON.stringify({
    file, errors: i.numErrors, warnings: i.numWarnings, infos: i.numInfos, hints: i.numHints, issues,
  }));
  if (i.numErrors > 0) failed = true;
}
process.exitCode = failed ? 1 : 0;

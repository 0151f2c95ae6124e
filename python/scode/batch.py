"""Batch conversion on Ray: every STEP/OBJ/PLY/STL/OFF/glb file under INPUT to .scode.

    python -m scode.batch INPUT OUTPUT [--address ADDRESS] [--timeout S] [--memory BYTES]

Each model is one Ray task (Ray Data, one block per file) that converts it in a child process
under a time limit (killed when it runs out) and an address-space limit (an allocation beyond
it fails), so a model that loops or blows up costs its own row and nothing else. Outputs are
``OUTPUT/<path under INPUT>.scode`` (``part.step`` -> ``part.step.scode``, written whole or not
at all) and the manifest ``OUTPUT/manifest/*.parquet``, one row per model: source, bytes in,
bytes out, max error, tolerance, encode seconds, status (``ok``, ``tolerance_missed``,
``failed``, ``timeout``, ``out_of_memory``), error message, skipped STEP faces, finish time.
Rows are written in parts as tasks finish, so an interrupted run keeps what it finished. A
mesh's face sidecar (``X.faces.json``, see :func:`scode.sidecar_path`) gives its faces'
surface types, as for the ``scode`` command.

A rerun skips every model the manifest already has a row for (same size, and for converted
models the .scode still there); ``--retry-failed`` converts the failures again. Read the
manifest with ``pyarrow.parquet.read_table(OUTPUT + "/manifest")`` (or pandas, DuckDB); a
source converted again has several rows, the latest ``finished_at`` is current.

Without ``--address`` a local Ray instance is started. On a cluster, install this package on
every node, start Ray there (``ray start --head`` on one, ``ray start --address HEAD:6379`` on
the others), keep INPUT and OUTPUT on a file system every node mounts at the same path, and
run the same command on any node with ``--address auto`` (or ``--address HEAD:6379``).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Dict, Iterable, List, Optional

EXTENSIONS = {
    ".step": "step",
    ".stp": "step",
    ".obj": "obj",
    ".ply": "ply",
    ".stl": "stl",
    ".off": "off",
    ".glb": "glb",
}

MANIFEST_DIR = "manifest"

# Manifest columns and their Arrow types (see the module documentation).
COLUMNS = [
    ("source", "string"),
    ("output", "string"),
    ("bytes_in", "int64"),
    ("bytes_out", "int64"),
    ("max_error", "float64"),
    ("tolerance", "float64"),
    ("encode_seconds", "float64"),
    ("status", "string"),
    ("error", "string"),
    ("skipped_faces", "int64"),
    ("finished_at", "float64"),
]

# Rows per manifest part: a part is written when this many rows finished (or at the end).
ROWS_PER_PART = 256


def discover(root: Path) -> List[Path]:
    """Every model file under ``root`` (a file is itself), in a fixed order."""
    if root.is_file():
        return [root] if root.suffix.lower() in EXTENSIONS else []
    return sorted(p for p in root.rglob("*") if p.is_file() and p.suffix.lower() in EXTENSIONS)


def output_name(relative: str) -> str:
    return relative + ".scode"


def read_manifest(output: Path):
    """The manifest's rows as an Arrow table, or None when there is none yet."""
    import pyarrow.parquet as pq

    d = output / MANIFEST_DIR
    if not d.is_dir() or not any(d.glob("*.parquet")):
        return None
    return pq.read_table(d)


def done_sources(output: Path, retry_failed: bool) -> Dict[str, int]:
    """Source (relative path) -> bytes_in of the models a rerun skips: the latest row of each
    source, if converted with its .scode still present, or failed unless ``retry_failed``."""
    table = read_manifest(output)
    if table is None:
        return {}
    latest: Dict[str, dict] = {}
    for row in table.to_pylist():
        prev = latest.get(row["source"])
        if prev is None or (row["finished_at"] or 0) >= (prev["finished_at"] or 0):
            latest[row["source"]] = row
    done = {}
    for source, row in latest.items():
        converted = row["status"] in ("ok", "tolerance_missed")
        if converted and not (output / row["output"]).is_file():
            continue
        if not converted and retry_failed:
            continue
        done[source] = row["bytes_in"]
    return done


def _limit_memory(max_bytes: int):
    def apply():
        if max_bytes > 0:
            resource.setrlimit(resource.RLIMIT_AS, (max_bytes, max_bytes))

    return apply


def convert_row(row: dict) -> dict:
    """One model: runs the worker in a child process under the time and memory limits and
    returns the manifest row. Never raises: every failure is a row."""
    started = time.time()
    result = {
        "source": row["source"],
        "output": row["output"],
        "bytes_in": row["bytes_in"],
        "bytes_out": None,
        "max_error": None,
        "tolerance": None,
        "encode_seconds": None,
        "status": "failed",
        "error": None,
        "skipped_faces": None,
        "finished_at": None,
    }
    cmd = [
        sys.executable,
        "-m",
        "scode.batch",
        "--worker",
        row["input_path"],
        row["output_path"],
        json.dumps(row["options"]),
    ]
    env = dict(os.environ, RAYON_NUM_THREADS=str(row["options"]["threads"]))
    try:
        proc = subprocess.run(
            cmd,
            capture_output=True,
            text=True,
            timeout=row["timeout"],
            preexec_fn=_limit_memory(row["memory"]),
            env=env,
        )
    except subprocess.TimeoutExpired:
        result["status"] = "timeout"
        result["error"] = f"did not finish within {row['timeout']:g} s"
        result["encode_seconds"] = time.time() - started
        result["finished_at"] = time.time()
        return result
    lines = proc.stdout.strip().splitlines()
    reply = None
    if proc.returncode == 0 and lines:
        try:
            reply = json.loads(lines[-1])
        except json.JSONDecodeError:
            reply = None
    if reply is not None:
        result.update(reply)
    else:
        tail = proc.stderr.strip().splitlines()[-3:]
        message = " | ".join(tail) or f"exit status {proc.returncode}"
        oom = "memory allocation" in proc.stderr or "MemoryError" in proc.stderr
        result["status"] = "out_of_memory" if oom else "failed"
        result["error"] = (
            f"exceeded the memory limit of {row['memory']} bytes: {message}" if oom else message
        )
        result["encode_seconds"] = time.time() - started
    result["finished_at"] = time.time()
    return result


def worker(input_path: str, output_path: str, options_json: str) -> int:
    """The child process: converts one file and prints its row fields as JSON. Errors the
    library reports are rows too (status ``failed`` with the message)."""
    import scode

    opts = json.loads(options_json)
    src = Path(input_path)
    fmt = EXTENSIONS[src.suffix.lower()]
    out = {"status": "failed"}
    t0 = time.perf_counter()
    try:
        # A mesh's face sidecar, as the scode command reads it: its surface types.
        sidecar = scode.sidecar_path(src) if fmt != "step" else None
        enc = scode.encode_file(
            src.read_bytes(),
            fmt,
            opts["tolerance"],
            opts["relative"],
            effort=opts["effort"],
            faces_json=sidecar.read_bytes() if sidecar else None,
        )
    except scode.ScodeError as e:
        out["error"] = f"{type(e).__name__}: {e}"
        out["encode_seconds"] = time.perf_counter() - t0
        print(json.dumps(out))
        return 0
    seconds = time.perf_counter() - t0
    dst = Path(output_path)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(f".{dst.name}.{os.getpid()}.tmp")
    tmp.write_bytes(enc.data)
    os.replace(tmp, dst)
    out.update(
        status="ok" if enc.within_tolerance else "tolerance_missed",
        bytes_out=len(enc.data),
        max_error=enc.max_error,
        tolerance=enc.tolerance,
        encode_seconds=seconds,
        skipped_faces=enc.skipped_faces,
        error=None
        if enc.within_tolerance
        else f"the fit missed the tolerance {enc.tolerance:.4g} against {enc.reference} "
        f"(max distance {enc.max_error:.4g})",
    )
    print(json.dumps(out))
    return 0


def write_part(output: Path, rows: List[dict], run_id: str, part: int) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = pa.schema([(name, pa.type_for_alias(t)) for name, t in COLUMNS])
    table = pa.Table.from_pylist([{k: r.get(k) for k, _ in COLUMNS} for r in rows], schema=schema)
    d = output / MANIFEST_DIR
    d.mkdir(parents=True, exist_ok=True)
    tmp = d / f".{run_id}-{part:05}.parquet.tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, d / f"{run_id}-{part:05}.parquet")


def plan(args) -> List[dict]:
    """The rows to convert: every model under INPUT the manifest does not have yet."""
    root = Path(args.input).resolve()
    output = Path(args.output).resolve()
    base = root if root.is_dir() else root.parent
    done = done_sources(output, args.retry_failed)
    options = {
        "tolerance": args.tolerance,
        "relative": not args.absolute,
        "effort": args.effort,
        "threads": args.cpus_per_task,
    }
    rows = []
    for path in discover(root):
        rel = path.relative_to(base).as_posix()
        size = path.stat().st_size
        if done.get(rel) == size:
            continue
        rows.append(
            {
                "source": rel,
                "output": output_name(rel),
                "input_path": str(path),
                "output_path": str(output / output_name(rel)),
                "bytes_in": size,
                "timeout": args.timeout,
                "memory": args.memory,
                "options": options,
            }
        )
    return rows


def run(args) -> int:
    output = Path(args.output).resolve()
    rows = plan(args)
    total = len(discover(Path(args.input).resolve()))
    print(
        f"{total} models under {args.input}; {total - len(rows)} already in the manifest; converting {len(rows)}"
    )
    if not rows:
        return 0
    import ray

    ray.init(
        address=args.address, log_to_driver=False, include_dashboard=False, ignore_reinit_error=True
    )
    ctx = ray.data.DataContext.get_current()
    ctx.enable_progress_bars = False
    # One block per file: each model is its own task, scheduled by its CPUs and memory.
    ds = ray.data.from_items(rows, override_num_blocks=len(rows))
    ds = ds.map(convert_row, num_cpus=args.cpus_per_task, memory=args.memory)
    run_id = time.strftime("%Y%m%dT%H%M%S") + "-" + uuid.uuid4().hex[:8]
    pending: List[dict] = []
    counts: Dict[str, int] = {}
    part = 0
    for row in ds.iter_rows():
        row = dict(row)
        counts[row["status"]] = counts.get(row["status"], 0) + 1
        mark = "" if row["status"] == "ok" else f" [{row['status']}] {row['error'] or ''}"
        print(f"{row['source']}: {row['bytes_in']} -> {row['bytes_out']} bytes{mark}", flush=True)
        pending.append(row)
        if len(pending) >= ROWS_PER_PART:
            write_part(output, pending, run_id, part)
            part += 1
            pending = []
    if pending:
        write_part(output, pending, run_id, part)
    summary = ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))
    print(f"converted {len(rows)} models: {summary}; manifest in {output / MANIFEST_DIR}")
    return 0


def parse_args(argv: Optional[Iterable[str]] = None):
    p = argparse.ArgumentParser(
        prog="python -m scode.batch",
        description="Convert every STEP/OBJ/PLY/STL/OFF/glb file under INPUT to .scode on Ray, "
        "with a Parquet manifest in OUTPUT/manifest.",
    )
    p.add_argument("input", help="folder (searched recursively) or one model file")
    p.add_argument("output", help="folder for the .scode files and the manifest")
    p.add_argument(
        "--address",
        default=None,
        help="Ray cluster to connect to ('auto', HOST:PORT); default: start a local one",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        help="seconds per model before it is killed (default 600)",
    )
    p.add_argument(
        "--memory",
        type=int,
        default=4 << 30,
        help="bytes of address space per model (and the Ray memory each task reserves; default 4 GiB)",
    )
    p.add_argument(
        "--cpus-per-task",
        type=int,
        default=1,
        help="CPUs (and encoder threads) per model (default 1)",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=1e-3,
        help="encode tolerance (default 1e-3 of the diagonal)",
    )
    p.add_argument(
        "--absolute",
        action="store_true",
        help="the tolerance is in model units, not relative to the diagonal",
    )
    p.add_argument("--effort", choices=["fast", "default", "max"], default="default")
    p.add_argument(
        "--retry-failed",
        action="store_true",
        help="convert models whose last row is a failure again",
    )
    return p.parse_args(argv)


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(*argv[1:4])
    return run(parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())

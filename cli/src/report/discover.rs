//! Which files the report measures: every mesh file `io::read_mesh` reads, and STEP files.

use std::path::{Path, PathBuf};

use scode::error::{Error, Result};
use scode::io::MeshFormat;

/// What the report will do with one input file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ModelSource {
    /// A mesh file `io::read_mesh` reads.
    Mesh,
    /// A STEP file (B-rep).
    Step,
    /// A file the report lists but cannot measure, with the reason (e.g. STEP today).
    Unsupported(String),
}

/// One model of the report.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ModelInput {
    pub path: PathBuf,
    /// Display name: the path relative to the directory it was found in (or the file name
    /// for files given directly), with `/` separators, so names are unique and stable.
    pub name: String,
    pub source: ModelSource,
}

/// How the report treats `path`: `Some` for models, `None` for files it ignores (sidecars,
/// YAML, notes). The one place to teach the report a new input kind.
pub fn classify(path: &Path) -> Option<ModelSource> {
    if MeshFormat::from_path(path).is_ok() {
        return Some(ModelSource::Mesh);
    }
    scode::io::step::is_step_path(path).then_some(ModelSource::Step)
}

/// Expands files and directories (recursively, in sorted order) into the models of the
/// report. Files given directly must be models; directories contribute the models they hold.
pub fn discover_models(inputs: &[PathBuf]) -> Result<Vec<ModelInput>> {
    let mut out = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let mut files = Vec::new();
            walk(input, &mut files)?;
            files.sort();
            for f in files {
                if let Some(source) = classify(&f) {
                    let rel = f.strip_prefix(input).unwrap_or(&f);
                    out.push(ModelInput {
                        name: display_name(rel),
                        path: f,
                        source,
                    });
                }
            }
        } else if input.is_file() {
            let source = classify(input).ok_or_else(|| {
                Error::input(input, "not a model file (expected a mesh or STEP file)")
            })?;
            let name = input
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| input.display().to_string());
            out.push(ModelInput {
                path: input.clone(),
                name,
                source,
            });
        } else {
            return Err(Error::input(input, "no such file or directory"));
        }
    }
    // The same name twice (one file given twice, or two directories with the same layout):
    // keep the names distinct so plots and table anchors do not collide.
    let mut seen = std::collections::BTreeMap::<String, usize>::new();
    for m in &mut out {
        let n = seen.entry(m.name.clone()).or_insert(0);
        *n += 1;
        if *n > 1 {
            m.name = format!("{} ({})", m.name, n);
        }
    }
    Ok(out)
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    for entry in entries {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        if path.is_dir() {
            walk(&path, out)?;
        } else {
            out.push(path);
        }
    }
    Ok(())
}

fn display_name(rel: &Path) -> String {
    rel.components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join("/")
}

/// A file-name-safe version of a model name (for plot files).
pub fn slug(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    s.trim_matches('_').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classifies_by_extension() {
        assert_eq!(classify(Path::new("a/b.obj")), Some(ModelSource::Mesh));
        assert_eq!(classify(Path::new("a/b.OFF")), Some(ModelSource::Mesh));
        assert_eq!(classify(Path::new("x.STP")), Some(ModelSource::Step));
        assert_eq!(classify(Path::new("a/x.step")), Some(ModelSource::Step));
        assert_eq!(classify(Path::new("x.faces.json")), None);
        assert_eq!(classify(Path::new("x.yml")), None);
        assert_eq!(classify(Path::new("README")), None);
        assert_eq!(slug("tess/screw_coarse.obj"), "tess_screw_coarse_obj");
    }

    #[test]
    fn walks_directories_sorted_and_rejects_non_models() {
        let dir = std::env::temp_dir().join(format!("scode-discover-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        for f in [
            "b.obj",
            "a.stl",
            "notes.md",
            "sub/c.step",
            "sub/c.faces.json",
        ] {
            std::fs::write(dir.join(f), b"").unwrap();
        }
        let models = discover_models(std::slice::from_ref(&dir)).unwrap();
        let names: Vec<&str> = models.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["a.stl", "b.obj", "sub/c.step"]);
        assert_eq!(models[2].source, ModelSource::Step);
        assert!(discover_models(&[dir.join("notes.md")]).is_err());
        assert!(discover_models(&[dir.join("missing.obj")]).is_err());
        let twice = discover_models(&[dir.join("b.obj"), dir.join("b.obj")]).unwrap();
        assert_eq!(twice[1].name, "b.obj (2)");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

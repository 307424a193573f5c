//! Guards for output paths: an output may not replace an input, lie inside a dataset (its images
//! are ground truth), lie inside an input folder, or take the name of a file a run owns.

use super::files::{is_run, OWNED_FILES};
use anyhow::{bail, Result};
use std::path::{Component, Path, PathBuf};

/// `path` made absolute: its deepest existing ancestor canonicalised (symbolic links and `..`
/// resolved), the rest appended with `.` and `..` applied lexically.
pub fn absolute(path: &Path) -> PathBuf {
    let joined = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(path)
    };
    let mut base = joined.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = base.canonicalize() {
            let mut out = c;
            for comp in rest.iter().rev() {
                match comp {
                    Component::ParentDir => {
                        out.pop();
                    }
                    Component::CurDir => {}
                    c => out.push(c.as_os_str()),
                }
            }
            return out;
        }
        match (base.parent(), base.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                base = parent;
            }
            _ => return joined,
        }
    }
}

/// Whether `dir` is a NeRF-synthetic dataset (holds a `transforms_*.json`).
pub fn is_dataset(dir: &Path) -> bool {
    [
        "transforms_train.json",
        "transforms_val.json",
        "transforms_test.json",
        "transforms.json",
    ]
    .iter()
    .any(|f| dir.join(f).is_file())
}

/// Refuse an output `out` that is one of `inputs` or lies inside one of them.
pub fn check_not_inside_inputs(out: &Path, inputs: &[&Path]) -> Result<()> {
    let abs_out = absolute(out);
    for input in inputs {
        let abs_in = absolute(input);
        if abs_out == abs_in {
            bail!(
                "--out {} is an input of this command ({}): it would be overwritten",
                out.display(),
                input.display()
            );
        }
        if abs_out.starts_with(&abs_in) {
            bail!(
                "--out {} lies inside the input {}: write it elsewhere",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// The dataset `path` lies in (or is), if any.
pub fn dataset_containing(path: &Path) -> Option<PathBuf> {
    absolute(path)
        .ancestors()
        .find(|a| is_dataset(a))
        .map(Path::to_path_buf)
}

/// Refuse an output folder (e.g. `render --out`) that is a file, an input, lies inside one, or
/// lies in a dataset.
pub fn check_output_dir(out: &Path, inputs: &[&Path]) -> Result<()> {
    if out.exists() && !out.is_dir() {
        bail!("--out {} is a file, not a folder", out.display());
    }
    check_placement(out, inputs)
}

/// Refuse an output (file or folder) that lies in a dataset, is an input or lies inside one.
fn check_placement(out: &Path, inputs: &[&Path]) -> Result<()> {
    if let Some(ds) = dataset_containing(out) {
        bail!(
            "--out {} lies inside the dataset {}: its images would be overwritten; choose a \
             folder outside it",
            out.display(),
            ds.display()
        );
    }
    check_not_inside_inputs(out, inputs)
}

/// Refuse an output file (`extract`, `export`) that is a folder, an input, inside an input
/// folder or a dataset, or a file a run owns (its checkpoints, marker, metrics, log). An
/// existing file that is none of these is replaced (atomically, by the writer).
pub fn check_output_file(out: &Path, inputs: &[&Path]) -> Result<()> {
    if out.is_dir() {
        bail!("--out {} is a folder; give a file name", out.display());
    }
    check_placement(out, inputs)?;
    if let (Some(parent), Some(name)) = (out.parent(), out.file_name()) {
        let parent = if parent.as_os_str().is_empty() {
            Path::new(".")
        } else {
            parent
        };
        if is_run(parent) && OWNED_FILES.iter().any(|f| name == *f) {
            bail!(
                "--out {} is a file of the run {} ({}); write it elsewhere",
                out.display(),
                parent.display(),
                name.to_string_lossy()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_never_replace_inputs_datasets_or_run_files() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        std::fs::create_dir(&run).unwrap();
        std::fs::write(run.join("run.json"), "{}").unwrap();
        let ckpt = run.join("plenoxels.npz");
        std::fs::write(&ckpt, "x").unwrap();
        let data = dir.path().join("data");
        std::fs::create_dir_all(data.join("test")).unwrap();
        std::fs::write(data.join("transforms_test.json"), "{}").unwrap();
        // Through a `..` and a relative path, still the same file.
        let odd = run.join("..").join("run").join("plenoxels.npz");
        for bad in [
            &ckpt,
            &odd,
            &run.join("surface.npz"),
            &run.join("metrics.json"),
        ] {
            assert!(
                check_output_file(bad, &[&ckpt]).is_err(),
                "{}",
                bad.display()
            );
        }
        assert!(check_output_file(&run, &[]).is_err());
        assert!(check_output_file(&data.join("test/r_0.png"), &[]).is_err());
        assert!(check_output_dir(&data.join("test"), &[]).is_err());
        assert!(check_output_dir(&data, &[]).is_err());
        check_output_file(&run.join("cloud.ply"), &[&ckpt]).unwrap();
        // An earlier output of the same kind is replaced, not refused (reruns of extract, demo).
        std::fs::write(run.join("cloud.ply"), "old").unwrap();
        check_output_file(&run.join("cloud.ply"), &[&ckpt]).unwrap();
        let e = check_output_file(&ckpt, &[]).unwrap_err().to_string();
        assert!(e.contains("is a file of the run"), "{e}");
        check_output_dir(&dir.path().join("renders"), &[&ckpt, &data]).unwrap();
        assert_eq!(absolute(&odd), absolute(&ckpt));
    }
}

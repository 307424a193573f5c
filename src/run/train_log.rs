//! The per-step training log `train_log.csv` of a run (a header line, then one row per step whose
//! first column is the step count). It is written row by row as training goes; a checkpoint
//! flushes it first, so every row up to the checkpoint's step is on disk. On resume the log is
//! cut back to the checkpoint's step (rows past it, and a row torn by a kill, are dropped,
//! atomically) before rows are appended again, so the log holds each step exactly once.

use anyhow::{Context, Result};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::Path;

/// The rows of `text` to keep when resuming at `step`: the header (which must equal `header`)
/// and the complete rows with a step ≤ `step`, up to the first row that is not.
pub fn cut(text: &str, header: &str, step: u32) -> Option<String> {
    let mut lines = text.split_inclusive('\n');
    let first = lines.next()?;
    if first.trim_end() != header {
        return None;
    }
    let fields = header.split(',').count();
    let mut out = first.to_string();
    for line in lines {
        let complete = line.ends_with('\n') && line.trim_end().split(',').count() == fields;
        let row_step = line.split(',').next().and_then(|s| s.parse::<u32>().ok());
        match row_step {
            Some(s) if complete && s <= step => out.push_str(line),
            _ => break,
        }
    }
    Some(out)
}

/// Open the training log at `path` for a run starting at `start_step`: a new log with `header`
/// at step 0 (or when there is none, or its header differs); otherwise the existing log cut back
/// to `start_step` and opened for appending.
pub fn open(path: &Path, header: &str, start_step: u32) -> Result<BufWriter<File>> {
    let kept = if start_step == 0 {
        None
    } else {
        match std::fs::read_to_string(path) {
            Ok(text) => cut(&text, header, start_step),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
        }
    };
    let kept = kept.unwrap_or_else(|| format!("{header}\n"));
    crate::io::atomic::write_bytes(path, kept.as_bytes())?;
    let file = OpenOptions::new()
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    Ok(BufWriter::new(file))
}

/// Flush the log (before a checkpoint, and at the end); an error names the file.
pub fn flush(log: &mut BufWriter<File>, path: &Path) -> Result<()> {
    log.flush()
        .and_then(|_| log.get_ref().sync_data())
        .with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resuming_cuts_rows_past_the_checkpoint_and_torn_rows() {
        let h = "step,mse";
        let text = "step,mse\n1,0.5\n2,0.4\n3,0.3\n4,0.2\n5,0.";
        assert_eq!(cut(text, h, 2).unwrap(), "step,mse\n1,0.5\n2,0.4\n");
        assert_eq!(
            cut(text, h, 4).unwrap(),
            "step,mse\n1,0.5\n2,0.4\n3,0.3\n4,0.2\n"
        );
        // A torn row merged with the next write: dropped with everything after it.
        let merged = "step,mse\n1,0.5\n2,0.43,0.3\n3,0.3\n";
        assert_eq!(cut(merged, h, 3).unwrap(), "step,mse\n1,0.5\n");
        assert!(cut("other,header\n1,2\n", h, 3).is_none());

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("train_log.csv");
        std::fs::write(&path, text).unwrap();
        let mut log = open(&path, h, 3).unwrap();
        writeln!(log, "4,0.25").unwrap();
        flush(&mut log, &path).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "step,mse\n1,0.5\n2,0.4\n3,0.3\n4,0.25\n"
        );
        drop(open(&path, h, 0).unwrap());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "step,mse\n");
    }
}

//! File output helpers.

use anyhow::{Context, Result};
use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `out` atomically: `<out>.tmp` in the same directory, fsync, rename. On any
/// error the temporary file is removed and `out` is untouched.
pub fn write_atomic(out: &Path, bytes: &[u8]) -> Result<()> {
    let mut tmp_name = out
        .file_name()
        .context("output path has no file name")?
        .to_owned();
    tmp_name.push(".tmp");
    let tmp = out.with_file_name(tmp_name);
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, out)?;
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty())
            && let Ok(d) = std::fs::File::open(dir)
        {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e).with_context(|| format!("cannot write {}", out.display()));
    }
    Ok(())
}

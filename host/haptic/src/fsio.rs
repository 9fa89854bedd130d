//! File output that never destroys: a command's output either appears whole or not at all,
//! and it never replaces an input, a link or anything that is not a regular file.

use anyhow::{Context, Result, bail};
use std::io::Write;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `out` atomically (a temporary file beside the target, fsync, rename), so
/// on any error `out` is untouched and no temporary file is left. What is at `out` decides:
///
/// - nothing: a new file is created (mode from the umask);
/// - a symbolic link: the file it points to is replaced, the link is kept;
/// - a regular file: it is replaced, keeping its permissions;
/// - anything else (a directory, FIFO, device node, socket): refused, nothing written;
/// - the same file as one of `inputs` (through any path or link): refused, so a command never
///   overwrites what it reads (pass the input itself to edit it in place deliberately, with
///   `inputs` empty).
pub fn write_atomic(out: &Path, bytes: &[u8], inputs: &[&Path]) -> Result<()> {
    let target = resolve(out)?;
    let existing = match std::fs::metadata(&target) {
        Ok(m) => Some(m),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(e).with_context(|| format!("cannot write {}", out.display())),
    };
    if let Some(m) = &existing {
        if !m.file_type().is_file() {
            bail!(
                "{}: not a regular file (a directory, FIFO, device or socket); refusing to \
                 replace it",
                out.display()
            );
        }
        for input in inputs {
            if let Ok(i) = std::fs::metadata(input)
                && (i.dev(), i.ino()) == (m.dev(), m.ino())
            {
                bail!(
                    "{}: that is the input {}; choose another output path (nothing was written)",
                    out.display(),
                    input.display()
                );
            }
        }
    }
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = target
        .file_name()
        .with_context(|| format!("{}: the output path has no file name", out.display()))?;
    let written = (|| -> std::io::Result<()> {
        let prefix = format!(".{}.", name.to_string_lossy());
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".tmp");
        if existing.is_none() {
            // As `File::create` does: 0666 less the umask (tempfile's own default is 0600).
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        let mut tmp = builder.tempfile_in(&dir)?;
        tmp.write_all(bytes)?;
        if let Some(m) = &existing {
            tmp.as_file()
                .set_permissions(std::fs::Permissions::from_mode(m.permissions().mode()))?;
        }
        tmp.as_file().sync_all()?;
        tmp.persist(&target).map_err(|e| e.error)?;
        if let Ok(d) = std::fs::File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    written.with_context(|| format!("cannot write {}", out.display()))
}

/// `out` with every symbolic link along the final component followed (the directories must
/// exist; the final file may not).
fn resolve(out: &Path) -> Result<PathBuf> {
    let mut path = out.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = std::fs::read_link(&path)
                    .with_context(|| format!("cannot read the link {}", path.display()))?;
                path = match path.parent() {
                    Some(dir) if link.is_relative() => dir.join(link),
                    _ => link,
                };
            }
            _ => return Ok(path),
        }
    }
    bail!("{}: too many levels of symbolic links", out.display())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::{FileTypeExt, symlink};

    #[test]
    fn a_new_file_gets_the_mode_file_create_would_give() {
        let dir = tempfile::tempdir().unwrap();
        let reference = dir.path().join("reference");
        std::fs::File::create(&reference).unwrap();
        let out = dir.path().join("new");
        write_atomic(&out, b"x", &[]).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&out), mode(&reference));
    }

    #[test]
    fn replaces_a_file_keeping_its_mode_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("scene.toml");
        std::fs::write(&f, "old").unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).unwrap();
        write_atomic(&f, b"new", &[]).unwrap();
        assert_eq!(std::fs::read_to_string(&f).unwrap(), "new");
        let mode = std::fs::metadata(&f).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn writes_through_a_link_and_keeps_the_link() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.bank");
        std::fs::write(&real, "old").unwrap();
        let link = dir.path().join("link.bank");
        symlink("real.bank", &link).unwrap();
        write_atomic(&link, b"new", &[]).unwrap();
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read_to_string(&real).unwrap(), "new");
        // A dangling link: its target is created.
        let dangling = dir.path().join("dangling");
        symlink("made.bank", &dangling).unwrap();
        write_atomic(&dangling, b"x", &[]).unwrap();
        assert_eq!(std::fs::read(dir.path().join("made.bank")).unwrap(), b"x");
    }

    #[test]
    fn refuses_inputs_and_special_files() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.toml");
        std::fs::write(&input, "keep").unwrap();
        let alias = dir.path().join("alias.toml");
        symlink(&input, &alias).unwrap();
        for out in [&input, &alias] {
            let e = write_atomic(out, b"x", &[&input]).unwrap_err().to_string();
            assert!(e.contains("that is the input"), "{e}");
        }
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "keep");
        let fifo = dir.path().join("fifo");
        let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: mkfifo(3) with a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        for out in [fifo.as_path(), dir.path(), Path::new("/dev/null")] {
            let e = write_atomic(out, b"x", &[]).unwrap_err().to_string();
            assert!(e.contains("not a regular file"), "{out:?}: {e}");
        }
        assert!(
            std::fs::symlink_metadata(&fifo)
                .unwrap()
                .file_type()
                .is_fifo()
        );
    }
}

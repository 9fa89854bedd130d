//! The on-disk cache of costly results (sampled banks, contact samples, display fields), and
//! FNV-1a, the hash its keys and the banks' scene ids are made of. Each caller keys its own
//! entries ([`crate::bank::cache`] its banks and samples, [`crate::display::fields`] its
//! fields): this module knows files, not what they hold.
//!
//! Files live in `$HAPTIC_CACHE_DIR`, else `$XDG_CACHE_HOME/haptic-host`, else
//! `~/.cache/haptic-host`, named `<kind>-<key>.bin` (the key in 16 hex digits) and written
//! atomically. Each new key adds a file, so each kind is bounded: when a file is stored, the
//! least recently used files of its kind go until the kind holds at most its
//! [`Store::kept`] (a hit counts as a use). An evicted entry only costs its next user the
//! computation.

use std::path::{Path, PathBuf};

/// FNV-1a 64 offset basis.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a, 64 bit, of `bytes`, continuing from `seed` ([`FNV_OFFSET`] to start).
pub fn fnv1a(seed: u64, bytes: &[u8]) -> u64 {
    bytes.iter().fold(seed, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The cache directory (module notes), `None` without a home directory.
pub fn cache_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("HAPTIC_CACHE_DIR") {
        return Some(PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return Some(PathBuf::from(d).join("haptic-host"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("haptic-host"))
}

/// One kind of cache file: its name prefix and how many are kept.
#[derive(Debug, Clone, Copy)]
pub struct Store {
    /// The files' name prefix, e.g. `bank` for `bank-<key>.bin`.
    pub kind: &'static str,
    /// Most files of the kind kept.
    pub kept: usize,
}

impl Store {
    /// The file of `key` in the cache directory, `None` without one.
    pub fn file(&self, key: u64) -> Option<PathBuf> {
        cache_dir().map(|d| d.join(format!("{}-{key:016x}.bin", self.kind)))
    }

    /// The entry of `key` read and decoded by `decode`, marked as used; `None` when there is no
    /// such file or `decode` refuses it (the caller computes it again).
    pub fn load<T, E>(&self, key: u64, decode: impl FnOnce(Vec<u8>) -> Result<T, E>) -> Option<T> {
        let f = self.file(key)?;
        let value = decode(std::fs::read(&f).ok()?).ok()?;
        touch(&f);
        Some(value)
    }

    /// Writes the entry of `key`, then evicts the least recently used files of the kind beyond
    /// [`Store::kept`]; a file that cannot be written only costs the next run the computation
    /// (a note on stderr says so).
    pub fn save(&self, key: u64, bytes: &[u8]) {
        let Some(f) = self.file(key) else {
            return;
        };
        let written = f
            .parent()
            .map(std::fs::create_dir_all)
            .transpose()
            .ok()
            .and_then(|_| crate::fsio::write_atomic(&f, bytes, &[]).ok());
        if written.is_none() {
            eprintln!("note: could not write the cache file {}", f.display());
            return;
        }
        if let Some(dir) = f.parent() {
            evict(dir, &format!("{}-", self.kind), self.kept);
        }
    }
}

/// Marks a cache hit as a use (its modification time), so eviction keeps what is in use.
fn touch(f: &Path) {
    let _ = std::fs::File::options()
        .append(true)
        .open(f)
        .and_then(|file| file.set_modified(std::time::SystemTime::now()));
}

/// Removes the oldest `<prefix>*.bin` files of `dir` (by modification time) beyond the
/// `kept` newest; errors (a file another process removed first) are ignored.
fn evict(dir: &Path, prefix: &str, kept: usize) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut files: Vec<_> = entries
        .filter_map(|e| e.ok())
        .filter(|e| {
            let n = e.file_name();
            let n = n.to_string_lossy();
            n.starts_with(prefix) && n.ends_with(".bin")
        })
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .collect();
    files.sort_by_key(|f| std::cmp::Reverse(f.0));
    for (_, old) in files.iter().skip(kept) {
        let _ = std::fs::remove_file(old);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// FNV-1a 64's published test vectors (Fowler, Noll and Vo: "" and "a", "foobar").
    #[test]
    fn fnv1a_matches_the_reference_vectors() {
        assert_eq!(fnv1a(FNV_OFFSET, b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(FNV_OFFSET, b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a(FNV_OFFSET, b"foobar"), 0x8594_4171_f739_67e8);
        // Hashing in parts is hashing the whole.
        assert_eq!(
            fnv1a(fnv1a(FNV_OFFSET, b"foo"), b"bar"),
            0x8594_4171_f739_67e8
        );
    }

    /// Eviction keeps the newest files of one kind and leaves the other kind and other files.
    #[test]
    fn eviction_keeps_the_most_recently_used() {
        let dir = tempfile::tempdir().unwrap();
        let t0 = std::time::SystemTime::now() - std::time::Duration::from_secs(100);
        for i in 0..5u64 {
            for kind in ["bank", "fields"] {
                let f = dir.path().join(format!("{kind}-{i:016x}.bin"));
                std::fs::write(&f, b"x").unwrap();
                let file = std::fs::File::options().append(true).open(&f).unwrap();
                file.set_modified(t0 + std::time::Duration::from_secs(i))
                    .unwrap();
            }
        }
        std::fs::write(dir.path().join("notes.txt"), b"kept").unwrap();
        // The oldest bank used again: it stays, the next oldest goes.
        touch(&dir.path().join(format!("bank-{:016x}.bin", 0)));
        evict(dir.path(), "bank-", 3);
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("bank-"))
            .collect();
        left.sort();
        let want: Vec<String> = [0u64, 3, 4]
            .iter()
            .map(|i| format!("bank-{i:016x}.bin"))
            .collect();
        assert_eq!(left, want);
        let fields = std::fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with("fields-")
            })
            .count();
        assert_eq!(fields, 5);
        assert!(dir.path().join("notes.txt").exists());
    }
}

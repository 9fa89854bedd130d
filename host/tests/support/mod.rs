//! Shared by the integration tests that drive a browser.

use std::path::PathBuf;

/// Debian's Chromium, or `$CHROMIUM`.
pub fn chromium() -> PathBuf {
    let p = std::env::var_os("CHROMIUM")
        .map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from);
    assert!(
        p.exists(),
        "{} not found: scripts/test-all.sh installs chromium (apt-get install -y chromium)",
        p.display()
    );
    p
}

//! An operator's confirmation before a step the host cannot check itself (`host device zero`:
//! the instrument is in its homing fixture; `host flash --set-bor`: write the option bytes):
//! a yes/no question at the terminal, or `--yes` for a script. Without a terminal on stdin and
//! without `--yes` the step is refused, never taken silently.

use anyhow::{Context, Result, bail};
use std::io::{BufRead, IsTerminal, Write};

/// Refuses unless `yes` (the `--yes` flag) or stdin is a terminal to ask at; `what` says what
/// would be confirmed, e.g. "that the instrument is in its homing fixture".
pub fn require_terminal_or_yes(yes: bool, what: &str) -> Result<()> {
    if yes || std::io::stdin().is_terminal() {
        return Ok(());
    }
    bail!(
        "nothing was done: this step needs you to confirm {what}, and stdin is not a terminal \
         to ask at; check it yourself and rerun with --yes"
    )
}

/// `true` with `yes`; else asks `question` on stderr and reads one line from stdin: `y` or
/// `yes` (any case) is a yes, anything else (an empty line, end of input) a no.
pub fn ask(yes: bool, question: &str) -> Result<bool> {
    if yes {
        return Ok(true);
    }
    eprint!("{question} [y/N] ");
    std::io::stderr().flush().ok();
    let mut line = String::new();
    std::io::stdin()
        .lock()
        .read_line(&mut line)
        .context("cannot read the answer from stdin")?;
    Ok(matches!(
        line.trim().to_ascii_lowercase().as_str(),
        "y" | "yes"
    ))
}

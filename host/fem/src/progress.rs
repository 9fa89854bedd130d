//! Progress of long computations, reported to whatever the caller shows (a terminal bar, a log,
//! nothing). The engine never draws anything itself.

/// Receives the progress of one computation: its total number of steps once known, then each
/// completed step. Implementations must be cheap; they are called from the computing thread.
pub trait Progress {
    /// The computation has `total` steps.
    fn start(&self, total: u64);
    /// `steps` more steps are done.
    fn advance(&self, steps: u64);
}

//! What a push of the paper's identifier did.

/// Outcome of one sub-fit in a push.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SubFit {
    /// Not enough usable points, or ill-conditioned: the previous estimate was kept.
    #[default]
    Held,
    /// Ran on a reduced set of unknowns (rank-deficient data); the rest was kept.
    Reduced,
    /// Ran in full.
    Ran,
}

impl SubFit {
    /// Lower-case name, for logs and Python.
    pub fn name(self) -> &'static str {
        match self {
            SubFit::Held => "held",
            SubFit::Reduced => "reduced",
            SubFit::Ran => "ran",
        }
    }
}

/// What the last `push` did. Small and `Copy`: reading it never allocates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PaperStatus {
    /// Samples pushed since construction or reset.
    pub samples: u64,
    /// The window holds its full N samples.
    pub window_full: bool,
    /// The window sums were refreshed exactly during this push.
    pub refreshed: bool,
    /// Step 1, kv and x0 (limited-memory RLS).
    pub line_fit: SubFit,
    /// Step 2, A and δ.
    pub rate_fit: SubFit,
    /// Step 3, n and β + γ.
    pub shape_fit: SubFit,
    /// Step 4, γ − β.
    pub return_fit: SubFit,
}

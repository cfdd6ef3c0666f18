//! Sizes every piece agrees on: the largest robot and the largest input file.

/// Largest scenario or attack file accepted, bytes.
pub const MAX_FILE_BYTES: u64 = 1 << 20;
/// Largest number of links a model may have (fixed-size message payloads).
pub const MAX_DOF: usize = 12;

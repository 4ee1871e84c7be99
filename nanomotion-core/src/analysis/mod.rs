//! Signal analysis toolkit (filled in by the analysis work).

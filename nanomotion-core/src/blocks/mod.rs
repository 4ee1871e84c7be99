//! Standard block library (filled in by the blocks work).

//! YAML graphs (in progress).
pub struct GraphSpec;
pub struct Graph;

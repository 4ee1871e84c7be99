//! The one place that talks to the YAML crate (`serde-saphyr`, pinned): its major
//! versions move fast, so everything else goes through these two functions.

use crate::error::GraphError;
use serde::de::DeserializeOwned;

/// Parse YAML text into `T`. `origin` (a file name) prefixes error messages, which
/// carry line and column and a snippet of the offending text.
///
/// Non-finite floats (`.nan`, `.inf`) are let through the parser on purpose (typetag
/// buffers maps and would otherwise report them without a location): every block
/// validates its own fields and names the one that is not finite.
pub fn from_str<T: DeserializeOwned>(text: &str, origin: &str) -> Result<T, GraphError> {
    let opts = serde_saphyr::options!(
        non_finite_float_policy: serde_saphyr::NonFiniteFloatPolicy::PassThrough,
    );
    serde_saphyr::from_str_with_options(text, opts).map_err(|e| GraphError::Parse {
        origin: origin.to_string(),
        message: e.to_string(),
    })
}

/// Serialise `value` as YAML.
pub fn to_string<T: serde::Serialize>(value: &T) -> Result<String, GraphError> {
    serde_saphyr::to_string(value).map_err(|e| GraphError::Parse {
        origin: "serialisation".into(),
        message: e.to_string(),
    })
}

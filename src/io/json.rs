//! JSON in: a bounded read, errors that name the file and the field, and the fields a schema
//! does not have.

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::{Error, Result};

/// Read and parse a JSON file; a missing file is [`Error::Missing`] with `what`.
pub fn read_json<T: DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = super::read::read_text(path, what)?;
    parse_json(&text, path)
}

/// Read and parse a JSON file, with the paths of the fields the schema does not have (other
/// programs may add their own; a misspelt field shows here).
pub fn read_json_noting_unknown<T: DeserializeOwned>(
    path: &Path,
    what: &str,
) -> Result<(T, Vec<String>)> {
    let text = super::read::read_text(path, what)?;
    let mut unknown = Vec::new();
    let de = &mut serde_json::Deserializer::from_str(&text);
    let mut note = |field: serde_ignored::Path| unknown.push(field.to_string());
    let value = serde_path_to_error::deserialize(serde_ignored::Deserializer::new(de, &mut note))
        .map_err(|e| Error::Json {
        path: path.to_path_buf(),
        field: e.path().to_string(),
        error: e.into_inner(),
    })?;
    Ok((value, unknown))
}

/// JSON text read from `origin` (a file, or where else it came from, such as a command-line
/// option), with the same errors as `read_json`.
pub fn parse_json<T: DeserializeOwned>(text: &str, origin: &Path) -> Result<T> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| Error::Json {
        path: origin.to_path_buf(),
        field: e.path().to_string(),
        error: e.into_inner(),
    })
}

/// Every value finite; an error names the first that is not (`field[i]` in a list).
pub fn check_finite(path: &Path, field: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::invalid(
            path,
            if values.len() > 1 {
                format!("{field}[{i}]")
            } else {
                field.to_string()
            },
            format!("must be a finite number, found {}", values[i]),
        )),
    }
}

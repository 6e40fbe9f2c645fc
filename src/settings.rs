//! Checking settings a user gave (a file, inline JSON or the defaults) when they are made:
//! every number finite and in its documented range, every count bounded, so that no value
//! reaches a loop or an allocation it could hang or exhaust. A rule broken is an
//! [`Error::Invalid`] naming the settings' source, the field (a JSON path such as
//! `search.samples`) and the range.

use std::path::Path;

use crate::error::{Error, Result, Shown};

/// The rules, applied field by field under a JSON path prefix.
pub struct Rules<'a> {
    source: &'a Path,
    prefix: String,
}

impl<'a> Rules<'a> {
    /// Rules for settings read from `source` (a file, or `--settings` for inline JSON).
    pub fn new(source: &'a Path) -> Rules<'a> {
        Rules {
            source,
            prefix: String::new(),
        }
    }

    /// The same rules for the fields of a nested object.
    pub fn within(&self, field: &str) -> Rules<'a> {
        Rules {
            source: self.source,
            prefix: self.path(field),
        }
    }

    fn path(&self, field: &str) -> String {
        if self.prefix.is_empty() {
            field.to_string()
        } else {
            format!("{}.{field}", self.prefix)
        }
    }

    fn fail(&self, field: &str, problem: String) -> Error {
        Error::invalid(self.source, self.path(field), problem)
    }

    /// A finite number in `[lo, hi]`.
    pub fn number(&self, field: &str, value: f64, lo: f64, hi: f64) -> Result<()> {
        if value.is_finite() && (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(self.fail(
                field,
                format!("must be a number from {lo} to {hi}, found {}", Shown(value)),
            ))
        }
    }

    /// A finite number above `lo` (exclusive) and at most `hi`.
    pub fn above(&self, field: &str, value: f64, lo: f64, hi: f64) -> Result<()> {
        if value.is_finite() && value > lo && value <= hi {
            Ok(())
        } else {
            Err(self.fail(
                field,
                format!(
                    "must be a number above {lo} and at most {hi}, found {}",
                    Shown(value)
                ),
            ))
        }
    }

    /// A count in `[lo, hi]`.
    pub fn count(&self, field: &str, value: u64, lo: u64, hi: u64) -> Result<()> {
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(self.fail(field, format!("must be from {lo} to {hi}, found {value}")))
        }
    }

    /// A list of `lo..=hi` entries.
    pub fn length(&self, field: &str, len: usize, lo: usize, hi: usize) -> Result<()> {
        if (lo..=hi).contains(&len) {
            Ok(())
        } else {
            Err(self.fail(
                field,
                format!("must have from {lo} to {hi} entries, found {len}"),
            ))
        }
    }

    /// A grid whose sides are each at most `side` and whose cells number at most `cells`.
    pub fn grid(&self, field: &str, sides: &[usize], side: usize, cells: usize) -> Result<()> {
        for (k, &n) in sides.iter().enumerate() {
            self.count(&format!("{field}[{k}]"), n as u64, 0, side as u64)?;
        }
        let total: usize = sides.iter().product();
        if total > cells {
            return Err(self.fail(
                field,
                format!("{sides:?} makes {total} poses, more than the {cells} allowed"),
            ));
        }
        Ok(())
    }
}

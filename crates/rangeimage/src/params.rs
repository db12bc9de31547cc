//! The error every stage's `Params::validate` returns.

/// A parameter outside its allowed values: which one, and what is wrong with the value.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field} {problem}")]
pub struct ParamError {
    /// The parameter as `stage.key` (e.g. `relax.t_d_px`).
    pub field: &'static str,
    /// What is wrong, e.g. `must be in 0..=64, got 70`.
    pub problem: String,
}

impl ParamError {
    /// The error for `field`, with `problem` saying what is wrong.
    #[must_use]
    pub fn new(field: &'static str, problem: impl Into<String>) -> Self {
        Self { field, problem: problem.into() }
    }

    /// Checks that `value` lies in `lo..=hi` (so is not NaN): "`field` must be in lo..=hi, got value".
    pub fn in_range<T: PartialOrd + std::fmt::Display + Copy>(
        field: &'static str,
        value: T,
        lo: T,
        hi: T,
    ) -> Result<(), Self> {
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(Self::new(field, format!("must be in {lo}..={hi}, got {value}")))
        }
    }

    /// Checks that `value` is finite and at least `min`: "`field` must be finite and ≥ min, got value".
    pub fn at_least(field: &'static str, value: f64, min: f64) -> Result<(), Self> {
        if value.is_finite() && value >= min {
            Ok(())
        } else {
            Err(Self::new(field, format!("must be finite and ≥ {min}, got {value}")))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_checks_reject_nan_and_name_the_bounds() {
        assert_eq!(ParamError::in_range("a.b", 1.0, 0.0, 1.0), Ok(()));
        assert_eq!(
            ParamError::in_range("a.i", 17u32, 0, 16).unwrap_err().to_string(),
            "a.i must be in 0..=16, got 17"
        );
        assert_eq!(
            ParamError::in_range("a.f", 90.5f32, 0.0, 90.0).unwrap_err().to_string(),
            "a.f must be in 0..=90, got 90.5"
        );
        let e = ParamError::in_range("a.b", f64::NAN, 0.0, 64.0).unwrap_err();
        assert_eq!(e.to_string(), "a.b must be in 0..=64, got NaN");
        assert_eq!(ParamError::at_least("a.c", 2.5, 1.0), Ok(()));
        assert!(ParamError::at_least("a.c", f64::INFINITY, 1.0).is_err());
        assert_eq!(
            ParamError::at_least("a.c", 0.5, 1.0).unwrap_err().to_string(),
            "a.c must be finite and ≥ 1, got 0.5"
        );
    }

    #[test]
    fn the_message_names_the_field() {
        let e = ParamError::new("relax.t_d_px", format!("must be in 0..=64, got {}", 70.0));
        assert_eq!(e.field, "relax.t_d_px");
        assert_eq!(e.to_string(), "relax.t_d_px must be in 0..=64, got 70");
    }
}

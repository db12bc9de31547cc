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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_message_names_the_field() {
        let e = ParamError::new("relax.t_d_px", format!("must be in 0..=64, got {}", 70.0));
        assert_eq!(e.field, "relax.t_d_px");
        assert_eq!(e.to_string(), "relax.t_d_px must be in 0..=64, got 70");
    }
}

//! The error of input that cannot be run: a parameter, a step size, a waveform, a state or a
//! batch that breaks a rule, with a message that names what and how to fix it. It becomes a
//! Python `ValueError` at the binding, and [`SimError::Input`](crate::integrate::task::SimError)
//! where a run is refused.

/// Input that cannot be run; the message names the parameter and the fix.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

impl From<String> for InputError {
    fn from(message: String) -> Self {
        InputError(message)
    }
}

impl From<&str> for InputError {
    fn from(message: &str) -> Self {
        InputError(message.to_string())
    }
}

/// The message, so that a test or a caller reads it as text (`err.contains("'m2'")`).
impl std::ops::Deref for InputError {
    type Target = str;
    fn deref(&self) -> &str {
        &self.0
    }
}

impl From<InputError> for String {
    fn from(e: InputError) -> Self {
        e.0
    }
}

/// `InputError` from a `format!` message: `return Err(input!("dt = {dt} must be positive"))`.
#[macro_export]
macro_rules! input {
    ($($arg:tt)*) => {
        $crate::error::InputError(format!($($arg)*))
    };
}

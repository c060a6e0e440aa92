//! Why a scenario could not be generated.

use crate::motion::pedestrians::SceneError;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ScenarioError {
    /// An option is out of range or options contradict each other.
    #[error("invalid scenario: {0}")]
    Invalid(String),
    /// The pedestrian scene could not be loaded or windowed.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A run asked for a number of events did not produce them in time.
    #[error("asked for {wanted} mix/observe events but got only {got} in {seconds:.1} s of motion{}", if *.ended { " (the recording ended)" } else { "" })]
    TooFewEvents {
        wanted: usize,
        got: usize,
        seconds: f64,
        ended: bool,
    },
}

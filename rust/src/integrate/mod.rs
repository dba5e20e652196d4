//! The integrators and what they share: a run as every runner sees it ([`task`]: the task, its
//! observer, how it ends), the method choice ([`method`]), step planning and divergence
//! messages ([`plan`]), the model as a right-hand side ([`model_rhs`]), the stepper interface
//! ([`stepper`]) and the steppers: fixed-step RK4, Dormand-Prince 5(4), Rodas4 and `auto`
//! ([`switching`], with [`stiffness`] and [`crawl`] watching an adaptive run); each explicit
//! method's coefficients once ([`tableau`]).

pub mod crawl;
pub mod dopri5;
pub mod method;
pub mod model_rhs;
pub mod plan;
pub mod rk4;
pub mod rodas4;
pub mod stepper;
pub mod stiffness;
pub mod switching;
pub mod tableau;
pub mod task;

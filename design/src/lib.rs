pub mod metrics;
pub mod servo;

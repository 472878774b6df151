//! Accuracy and cost: the sampling-quality metrics of non-redundant-rendering.txt §6.1.2.

pub mod sampling;

pub use sampling::{sampling_metrics, SamplingMetrics};

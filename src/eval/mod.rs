//! Extraction and evaluation of point clouds: level-set point extraction with dense virtual rays
//! ([`extract`]), nearest neighbours through a k-d tree ([`knn`]), greedy radius thinning
//! ([`thin`]) and the Chamfer / F-score metrics of method.md §4 ([`metrics`]).

pub mod extract;
pub mod knn;
pub mod metrics;
pub mod thin;

pub use knn::PointIndex;
pub use metrics::{evaluate, EvalOptions, Metrics};
pub use thin::{thin, thin_levels};

//! Extraction and evaluation of point clouds: level-set point extraction with dense virtual rays
//! ([`extract`]), greedy radius thinning ([`thin`], neighbours through
//! [`crate::math::knn`]), the trimming of surfaces hidden from every training view ([`hidden`])
//! and of the outermost level's halo around thick parts ([`outer_level`]), thin sheets' two
//! faces moved onto the sheet ([`sheets`]), the Chamfer / F-score metrics of method.md §4
//! ([`metrics`]) and their split over a scene's objects ([`objects`]).

pub mod colour;
pub mod extract;
pub mod hidden;
pub mod metrics;
pub mod objects;
pub mod outer_level;
pub mod sheets;
pub mod thin;

pub use metrics::{evaluate, evaluate_groups, evaluate_indexed, EvalOptions, Metrics};
pub use thin::{thin, thin_levels};

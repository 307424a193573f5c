//! What a command owns on disk and the limits it runs within: run directories (marker, lock,
//! file names, refusal rules, `--overwrite`), guards for output paths, replacing a whole folder
//! (built beside, swapped in when complete), the training log's resume-time cut, the dataset
//! identity a run records and the check that a command's dataset is the run's, memory estimates
//! for flags that size allocations, the thread that writes checkpoints while training goes on,
//! and the stop a signal asks of a training loop.

pub mod dir;
pub mod files;
pub mod identity;
pub mod interrupt;
pub mod lock;
pub mod memory;
pub mod outputs;
pub mod replace;
pub mod same_data;
pub mod train_log;

pub use dir::{read_info, Open, RunDir, RunInfo, RunStage};

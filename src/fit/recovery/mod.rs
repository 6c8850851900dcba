//! The global iterations that tie the caches, the fits and the hierarchy together (§4.1 of the
//! notes): what a recovery takes and gives (`options.rs`), the loop as a value (`run.rs`), one
//! global iteration in its phases (`iterate.rs`), the state needed to continue
//! (`checkpoint.rs`), and the entry points (`recover.rs`).

pub mod checkpoint;
mod iterate;
pub mod options;
pub mod recover;
pub mod run;

pub use checkpoint::{fingerprint, Checkpoint, CHECKPOINT_VERSION};
pub use options::{GreyCard, LogLine, PhotoView, RecoverError, RecoverOptions, Recovery, ViewFit};
pub use recover::{recover, recover_resumable};
pub use run::{texture_stem, RecoveryLoop};

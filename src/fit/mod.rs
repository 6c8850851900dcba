//! The recovery engine: per-group incident-radiance caches, the solvers, the hierarchy's state
//! machine, and the global iterations that tie them together (§4 of the notes).

pub mod cache;
pub mod detail;
pub mod error;
pub mod event;
pub mod evidence;
pub mod fitter;
pub mod group;
pub mod hierarchy;
pub mod level;
pub mod objective;
pub mod params;
pub mod periodic;
pub mod pseudo;
pub mod recovery;
pub mod schedule;
pub mod solve;
pub mod stray;
pub mod texture;
pub mod uncertainty;
pub mod unseen;
pub mod views;

pub use event::Event;
pub use group::{GroupState, Status};
pub use level::{HierarchyOptions, Level};
pub use params::GroupParams;
pub use recovery::{
    recover, recover_resumable, Checkpoint, RecoverError, RecoverOptions, Recovery,
};

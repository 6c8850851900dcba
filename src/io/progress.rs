//! Progress of long work (renders, recoveries), reported rather than drawn: the library calls a
//! [`Sink`] that its caller installs ([`set_sink`]), and draws nothing itself. The command line
//! installs one that draws bars on a terminal; without one, progress goes nowhere.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};

/// Where a piece of work is: `done` of `total` steps of `task` (`"render"`, `"recover"`), with
/// a short `message` (`"iteration 3/16"`); `finished` once, at the end.
#[derive(Clone, Copy, Debug)]
pub struct Progress<'a> {
    pub task: &'a str,
    pub done: u64,
    pub total: u64,
    pub message: &'a str,
    pub finished: bool,
}

/// Receives progress from any thread (renders report from their worker threads).
pub trait Sink: Send + Sync {
    fn progress(&self, p: &Progress);
}

static SINK: RwLock<Option<Arc<dyn Sink>>> = RwLock::new(None);

/// Installs the process's progress sink (None: progress goes nowhere, the default). Work that
/// takes its own callback (the front door's calls, through their observer) reports there instead.
pub fn set_sink(sink: Option<Arc<dyn Sink>>) {
    if let Ok(mut s) = SINK.write() {
        *s = sink;
    }
}

fn installed() -> Option<Arc<dyn Sink>> {
    SINK.read().ok().and_then(|s| s.clone())
}

/// Where a [`Bar`] reports.
type Report<'a> = Box<dyn Fn(&Progress) + Send + Sync + 'a>;

/// A counter of `total` steps that reports each change: to the installed sink, to a callback,
/// or nowhere.
pub struct Bar<'a> {
    task: String,
    total: u64,
    done: AtomicU64,
    message: Mutex<String>,
    report: Option<Report<'a>>,
}

impl Bar<'static> {
    /// A bar reporting to the process's sink if `show`.
    pub fn new(total: u64, task: &str, show: bool) -> Bar<'static> {
        let sink = installed().filter(|_| show);
        Bar::with(
            total,
            task,
            sink.map(|s| Box::new(move |p: &Progress| s.progress(p)) as Report<'static>),
        )
    }
}

impl<'a> Bar<'a> {
    /// A bar reporting to `report`, whatever the process's sink is.
    pub fn to(total: u64, task: &str, report: impl Fn(&Progress) + Send + Sync + 'a) -> Bar<'a> {
        Bar::with(total, task, Some(Box::new(report)))
    }

    fn with(total: u64, task: &str, report: Option<Report<'a>>) -> Bar<'a> {
        Bar {
            task: task.to_string(),
            total,
            done: AtomicU64::new(0),
            message: Mutex::new(String::new()),
            report,
        }
    }

    fn report(&self, done: u64, finished: bool) {
        if let Some(r) = &self.report {
            let message = self.message.lock().map(|m| m.clone()).unwrap_or_default();
            r(&Progress {
                task: &self.task,
                done,
                total: self.total,
                message: &message,
                finished,
            });
        }
    }

    pub fn inc(&self, n: u64) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        self.report(done, false);
    }

    pub fn set_message(&self, message: impl Into<String>) {
        if let Ok(mut m) = self.message.lock() {
            *m = message.into();
        }
        self.report(self.done.load(Ordering::Relaxed), false);
    }

    /// The end of the work: reported once.
    pub fn finish_and_clear(&self) {
        self.report(self.done.load(Ordering::Relaxed), true);
    }
}

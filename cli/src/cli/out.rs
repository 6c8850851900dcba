//! Terminal output. Standard output goes through [`print`], which ends the program quietly when
//! the reader has gone (`matfit info … | head -1`), as ripgrep does; warnings go through
//! [`warn`], which also keeps them so that a long command can repeat them at its end.

use std::io::Write;
use std::sync::Mutex;

static WARNINGS: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Writes to standard output; a closed pipe ends the program with status 0, any other write
/// error with status 2.
pub fn print(args: std::fmt::Arguments) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|_| out.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        // Standard error may be gone too: nothing more to say then.
        let _ = writeln!(
            std::io::stderr(),
            "error: cannot write to standard output: {e}"
        );
        std::process::exit(2);
    }
}

/// `println!` through [`print`].
#[macro_export]
macro_rules! outln {
    () => { $crate::cli::out::print(format_args!("\n")) };
    ($($t:tt)*) => { $crate::cli::out::print(format_args!("{}\n", format_args!($($t)*))) };
}

/// Prints `warning: MSG` to standard error now and keeps it for [`repeat_warnings`].
pub fn warn(msg: impl Into<String>) {
    let msg = msg.into();
    let _ = writeln!(std::io::stderr(), "warning: {msg}");
    remember(msg);
}

fn remember(msg: String) {
    if let Ok(mut w) = WARNINGS.lock() {
        if !w.contains(&msg) {
            w.push(msg);
        }
    }
}

/// Repeats every warning given so far (after a long output they would have scrolled away).
pub fn repeat_warnings() {
    let w = WARNINGS.lock().map(|w| w.clone()).unwrap_or_default();
    if w.is_empty() {
        return;
    }
    let mut err = std::io::stderr().lock();
    let _ = writeln!(
        err,
        "\n{} warning{} (repeated):",
        w.len(),
        if w.len() == 1 { "" } else { "s" }
    );
    for m in &w {
        let _ = writeln!(err, "warning: {m}");
    }
}

/// The log's lines in the style of [`warn`]: `warning: MSG`, `error: MSG`, `info: MSG`, so that
/// the library's warnings and the command's read alike; debug and trace lines (`MATFIT_LOG`)
/// also name their module.
pub struct LogFormat;

impl<S, N> tracing_subscriber::fmt::FormatEvent<S, N> for LogFormat
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
    N: for<'a> tracing_subscriber::fmt::FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &tracing_subscriber::fmt::FmtContext<'_, S, N>,
        mut writer: tracing_subscriber::fmt::format::Writer<'_>,
        event: &tracing::Event<'_>,
    ) -> std::fmt::Result {
        use tracing::Level;
        let meta = event.metadata();
        match *meta.level() {
            Level::ERROR => write!(writer, "error: ")?,
            Level::WARN => write!(writer, "warning: ")?,
            Level::INFO => write!(writer, "info: ")?,
            Level::DEBUG => write!(writer, "debug {}: ", meta.target())?,
            Level::TRACE => write!(writer, "trace {}: ", meta.target())?,
        }
        ctx.field_format().format_fields(writer.by_ref(), event)?;
        writeln!(writer)
    }
}

/// The log's writer: standard error, keeping the library's warnings ([`LogFormat`]'s
/// `warning: ` lines) for [`repeat_warnings`].
pub struct LogWriter;

impl Write for LogWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let text = String::from_utf8_lossy(buf);
        for line in text.lines() {
            if let Some(msg) = line.strip_prefix("warning: ") {
                remember(strip_ansi(msg));
            }
        }
        std::io::stderr().write_all(buf)?;
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

fn strip_ansi(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for d in chars.by_ref() {
                if d.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// What the library's calls report, on the terminal: lines on standard output, warnings as
/// [`warn`] gives them, progress as bars on standard error (hidden when it is not a terminal).
pub struct Term {
    /// The command that continues an interrupted `recover` (said on Ctrl-C once fitting).
    pub resume: Option<String>,
    /// Print the library's lines (`demo` prints its own).
    pub messages: bool,
}

/// [`Term`] for most commands.
pub const TERM: Term = Term {
    resume: None,
    messages: true,
};

impl matfit::Observer for Term {
    fn message(&self, text: &str) {
        if self.messages {
            crate::outln!("{text}");
        }
    }
    fn warning(&self, text: &str) {
        warn(text);
    }
    fn progress(&self, p: &matfit::Progress) {
        BARS.show(p);
    }
    fn fitting(&self) {
        if let Some(cmd) = &self.resume {
            super::checks::on_interrupt_say_resume(cmd.clone());
        }
    }
}

/// The progress bar on the terminal: one at a time, for the task that last reported.
pub struct Bars(Mutex<Option<(String, indicatif::ProgressBar)>>);

pub static BARS: Bars = Bars(Mutex::new(None));

impl Bars {
    pub fn show(&self, p: &matfit::Progress) {
        let Ok(mut bar) = self.0.lock() else { return };
        if bar.as_ref().is_some_and(|(task, _)| task != p.task) {
            if let Some((_, pb)) = bar.take() {
                pb.finish_and_clear();
            }
        }
        if p.finished {
            if let Some((_, pb)) = bar.take() {
                pb.finish_and_clear();
            }
            return;
        }
        let (_, pb) = bar.get_or_insert_with(|| {
            let pb = indicatif::ProgressBar::new(p.total);
            pb.set_style(
                indicatif::ProgressStyle::with_template(
                    "{msg:>10} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}",
                )
                .unwrap()
                .progress_chars("=> "),
            );
            (p.task.to_string(), pb)
        });
        pb.set_position(p.done);
        let msg = if p.message.is_empty() {
            p.task
        } else {
            p.message
        };
        pb.set_message(msg.to_string());
    }
}

/// [`BARS`] as the library's progress sink, for the work that reports to no observer.
pub struct BarSink;

impl matfit::io::progress::Sink for BarSink {
    fn progress(&self, p: &matfit::Progress) {
        BARS.show(p);
    }
}

//! The `matfit` program: parses the command line (`cli`) and reports errors.

mod cli;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("MATFIT_LOG")
                .unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(|| cli::out::LogWriter)
        .with_ansi(false)
        .event_format(cli::out::LogFormat)
        .init();
    // The library draws nothing: its progress comes here.
    matfit::io::progress::set_sink(Some(std::sync::Arc::new(cli::out::BarSink)));
    if let Some(n) = args.threads {
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
        {
            eprintln!("error: cannot set up {n} threads: {e}");
            return ExitCode::from(2);
        }
    }
    match cli::run(args.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

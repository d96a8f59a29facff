//! What `gems` prints for a person, and the log file each run keeps beside its outputs.
//!
//! Two `tracing` layers:
//! - **the console** (stderr): by default one short line per event at INFO and above, without
//!   timestamps or module paths, floats rounded to four significant digits, warnings and errors
//!   prefixed as such; lines are written with the progress bars lifted out of the way
//!   ([`gems_pipeline::progress::suspend`]), so a bar stays one line at the bottom. `-v` shows
//!   DEBUG with timestamps and targets, `-vv` everything; `RUST_LOG` overrides the filter.
//! - **the log file** (`gems.log` in the command's output folder, appended to): DEBUG for gems,
//!   INFO for the libraries beneath, full timestamps and full precision. Events before the
//!   command knows its output folder are held in memory and written when it does ([`log_to`]).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields, MakeWriter};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::registry::LookupSpan;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer};

/// The log file's name in an output folder.
pub const LOG_FILE: &str = "gems.log";

/// Installs the console and log-file layers for `verbose` (the number of `-v`).
pub fn init(verbose: u8) {
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let console_filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| {
        EnvFilter::new(match verbose {
            0 => "warn,gems=info",
            1 => "info,gems=debug",
            _ => "trace",
        })
    });
    let console = if verbose == 0 {
        tracing_subscriber::fmt::layer()
            .with_writer(ConsoleWriter)
            .with_ansi(ansi)
            .event_format(Readable { ansi })
            .boxed()
    } else {
        tracing_subscriber::fmt::layer()
            .with_writer(ConsoleWriter)
            // Escape codes only for a person at a terminal, never into a pipe.
            .with_ansi(ansi)
            .with_timer(tracing_subscriber::fmt::time::uptime())
            .boxed()
    };
    let file = tracing_subscriber::fmt::layer()
        .with_writer(LogWriter)
        .with_ansi(false)
        .with_filter(EnvFilter::new("info,gems=debug"));
    tracing_subscriber::registry()
        .with(console.with_filter(console_filter))
        .with(file)
        .init();
}

/// Sends this process's log to `<dir>/gems.log` (appending; the folder is created), with what
/// was logged before; returns the file's path.
pub fn log_to(dir: &Path) -> Result<PathBuf, gems_fs::FsError> {
    let path = dir.join(LOG_FILE);
    let fs_error = |source| gems_fs::FsError {
        path: path.clone(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(fs_error)?;
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .map_err(fs_error)?;
    let mut sink = LOG.lock().unwrap_or_else(|e| e.into_inner());
    writeln!(
        file,
        "==== gems {} — {}",
        env!("CARGO_PKG_VERSION"),
        std::env::args().collect::<Vec<_>>().join(" ")
    )
    .map_err(fs_error)?;
    if let LogSink::Held(held) = &*sink {
        file.write_all(held).map_err(fs_error)?;
    }
    *sink = LogSink::File(file);
    Ok(path)
}

/// Where the log-file layer's lines go: held in memory until [`log_to`] names the file.
enum LogSink {
    Held(Vec<u8>),
    File(std::fs::File),
}

static LOG: Mutex<LogSink> = Mutex::new(LogSink::Held(Vec::new()));

/// Lines held before the output folder is known are kept up to this size, then dropped.
const HELD_LIMIT: usize = 4 << 20;

struct LogWriter;

impl Write for LogWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let mut sink = LOG.lock().unwrap_or_else(|e| e.into_inner());
        match &mut *sink {
            LogSink::Held(held) if held.len() + buf.len() <= HELD_LIMIT => {
                held.extend_from_slice(buf);
            }
            LogSink::Held(_) => {}
            // A log line that cannot be written must not stop the run; the console has it.
            LogSink::File(f) => {
                let _ = f.write_all(buf);
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl<'a> MakeWriter<'a> for LogWriter {
    type Writer = LogWriter;
    fn make_writer(&'a self) -> LogWriter {
        LogWriter
    }
}

/// stderr, with the progress bars cleared for the write and redrawn after it.
struct ConsoleWriter;

impl Write for ConsoleWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        gems_pipeline::progress::suspend(|| std::io::stderr().write_all(buf))?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

impl<'a> MakeWriter<'a> for ConsoleWriter {
    type Writer = ConsoleWriter;
    fn make_writer(&'a self) -> ConsoleWriter {
        ConsoleWriter
    }
}

/// The default console line: `[warning: ]message (field value, field value)`.
struct Readable {
    ansi: bool,
}

impl<S, N> FormatEvent<S, N> for Readable
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        _ctx: &FmtContext<'_, S, N>,
        mut writer: Writer<'_>,
        event: &Event<'_>,
    ) -> std::fmt::Result {
        let (prefix, colour) = match *event.metadata().level() {
            Level::ERROR => ("error: ", "\x1b[1;31m"),
            Level::WARN => ("warning: ", "\x1b[1;33m"),
            Level::INFO => ("", ""),
            Level::DEBUG => ("debug: ", "\x1b[2m"),
            Level::TRACE => ("trace: ", "\x1b[2m"),
        };
        if self.ansi && !colour.is_empty() {
            write!(writer, "{colour}{prefix}\x1b[0m")?;
        } else {
            write!(writer, "{prefix}")?;
        }
        let mut fields = Fields::default();
        event.record(&mut fields);
        writeln!(writer, "{}", fields.line())
    }
}

/// An event's message and its other fields, floats rounded.
#[derive(Default)]
struct Fields {
    message: String,
    rest: Vec<(&'static str, String)>,
}

impl Fields {
    fn line(&self) -> String {
        if self.rest.is_empty() {
            return self.message.clone();
        }
        let rest: Vec<String> = self
            .rest
            .iter()
            .map(|(name, value)| format!("{} {value}", name.replace('_', " ")))
            .collect();
        if self.message.is_empty() {
            rest.join(", ")
        } else {
            format!("{} ({})", self.message, rest.join(", "))
        }
    }
}

impl Visit for Fields {
    fn record_f64(&mut self, field: &Field, value: f64) {
        self.rest.push((field.name(), round(value)));
    }

    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            value.clone_into(&mut self.message);
        } else {
            self.rest.push((field.name(), value.to_owned()));
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.message = format!("{value:?}");
        } else {
            self.rest.push((field.name(), format!("{value:?}")));
        }
    }
}

/// `v` with four significant digits (whole numbers without a fraction): a person reads
/// `1.239 px`, not `1.2393794339894986`.
fn round(v: f64) -> String {
    if !v.is_finite() {
        return v.to_string();
    }
    if v.fract() == 0.0 && v.abs() < 1e15 {
        return format!("{v:.0}");
    }
    let magnitude = v.abs().log10().floor() as i32;
    let decimals = (3 - magnitude).clamp(0, 6) as usize;
    format!("{v:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_are_rounded_to_four_significant_digits() {
        assert_eq!(round(1.2393794339894986), "1.239");
        assert_eq!(round(207.84609690826528), "207.8");
        assert_eq!(round(0.4022132456302643), "0.4022");
        assert_eq!(round(30.0), "30");
        assert_eq!(round(-12345.678), "-12346");
        assert_eq!(round(0.000123456), "0.000123");
        assert_eq!(round(f64::NAN), "NaN");
    }

    /// The console line of one event, through the real layer and formatter.
    fn console_line(emit: impl FnOnce()) -> String {
        #[derive(Clone, Default)]
        struct Buf(std::sync::Arc<Mutex<Vec<u8>>>);
        impl Write for Buf {
            fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
                self.0.lock().unwrap().extend_from_slice(b);
                Ok(b.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let buf = Buf::default();
        let sink = buf.clone();
        let layer = tracing_subscriber::fmt::layer()
            .with_writer(move || sink.clone())
            .event_format(Readable { ansi: false });
        let subscriber = tracing_subscriber::registry().with(layer);
        tracing::subscriber::with_default(subscriber, emit);
        String::from_utf8(buf.0.lock().unwrap().clone()).unwrap()
    }

    #[test]
    fn a_console_line_is_the_message_then_rounded_fields() {
        let line = console_line(|| {
            tracing::info!(
                registered = 24,
                reprojection_px = 1.2393794339895008,
                dir = %"out/sfm",
                "sfm done"
            );
        });
        assert_eq!(
            line,
            "sfm done (registered 24, reprojection px 1.239, dir out/sfm)\n"
        );
        let warn = console_line(|| tracing::warn!("no --lpips weights given"));
        assert_eq!(warn, "warning: no --lpips weights given\n");
    }
}

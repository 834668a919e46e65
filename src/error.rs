//! The library's one error type: a kind a caller can match on, and the message the records and
//! the command line print. Messages read as a chain, outermost first ("cannot read a.fits:
//! No such file or directory"), and that chain is the whole `Display`: `source()` is left
//! empty so that a reporter walking sources (anyhow's `{:#}`) does not print it twice.

use std::fmt::Display;

/// What went wrong. Marked non-exhaustive: kinds may be added.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed: missing, no permission, disk full. `error.kind()`
    /// says which.
    #[error("{}", join(context, &chain(error)))]
    Io {
        /// What was being done ("cannot read a.fits"); empty when nothing was added.
        context: String,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// An input file's contents cannot be used: an image, a FITS header or its keywords, a
    /// record or truth file, a directory of inputs.
    #[error("{0}")]
    Input(String),
    /// The star catalog or the distance table built from it.
    #[error("{0}")]
    Catalog(String),
    /// A camera model or a setting out of its range.
    #[error("{0}")]
    Config(String),
    /// An output file gpustar refuses to write or resume (not its own, another format, locked,
    /// torn), or a product path it cannot use.
    #[error("{0}")]
    Output(String),
    /// The GPU: no adapter, a kernel that does not build, a device lost in a run.
    #[error("{0}")]
    Gpu(String),
    /// A bug in gpustar: a stage panicked on an input (its record says so, and the run goes on).
    #[error("{0}")]
    Internal(String),
}

/// A copy of the error for every frame that shares it (a frame size's solver, a dark, a GPU
/// table): the same kind and message. An I/O error is copied as its kind and its message, as
/// `std::io::Error` cannot be cloned.
impl Clone for Error {
    fn clone(&self) -> Self {
        match self {
            Error::Io { context, error } => Error::Io {
                context: context.clone(),
                error: std::io::Error::new(error.kind(), chain(error)),
            },
            Error::Input(m) => Error::Input(m.clone()),
            Error::Catalog(m) => Error::Catalog(m.clone()),
            Error::Config(m) => Error::Config(m.clone()),
            Error::Output(m) => Error::Output(m.clone()),
            Error::Gpu(m) => Error::Gpu(m.clone()),
            Error::Internal(m) => Error::Internal(m.clone()),
        }
    }
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// The same kind of error with `context` in front of its message.
    pub fn context(self, context: impl Display) -> Error {
        let c = context.to_string();
        match self {
            Error::Io { context, error } => Error::Io {
                context: join(&c, &context),
                error,
            },
            Error::Input(m) => Error::Input(join(&c, &m)),
            Error::Catalog(m) => Error::Catalog(join(&c, &m)),
            Error::Config(m) => Error::Config(join(&c, &m)),
            Error::Output(m) => Error::Output(join(&c, &m)),
            Error::Gpu(m) => Error::Gpu(join(&c, &m)),
            Error::Internal(m) => Error::Internal(join(&c, &m)),
        }
    }
}

impl From<std::io::Error> for Error {
    fn from(error: std::io::Error) -> Self {
        Error::Io {
            context: String::new(),
            error,
        }
    }
}

/// `a: b`, or whichever of them is not empty.
fn join(a: &str, b: &str) -> String {
    match (a.is_empty(), b.is_empty()) {
        (true, _) => b.to_string(),
        (_, true) => a.to_string(),
        _ => format!("{a}: {b}"),
    }
}

/// An error and its sources, joined by ": " (the form anyhow's `{:#}` prints).
pub(crate) fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut next = e.source();
    while let Some(cause) = next {
        s.push_str(": ");
        s.push_str(&cause.to_string());
        next = cause.source();
    }
    s
}

/// Context for results: an I/O error becomes [`Error::Io`]; the library's own errors keep
/// their kind and gain the context in front.
pub trait Context<T> {
    /// Put `context` in front of the error's message.
    fn context<C: Display>(self, context: C) -> Result<T>;
    /// Put `f()` in front of the error's message; `f` runs only on an error.
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T> Context<T> for std::result::Result<T, std::io::Error> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.map_err(|error| Error::Io {
            context: context.to_string(),
            error,
        })
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|error| Error::Io {
            context: f().to_string(),
            error,
        })
    }
}

impl<T> Context<T> for Result<T> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.map_err(|e| e.context(context))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|e| e.context(f()))
    }
}

/// A foreign error (a parser's, a decoder's) as one of ours: `toml::from_str(t).into_kind(Error::Config)`.
pub(crate) trait IntoKind<T> {
    fn into_kind(self, kind: fn(String) -> Error) -> Result<T>;
}

impl<T, E: std::error::Error> IntoKind<T> for std::result::Result<T, E> {
    fn into_kind(self, kind: fn(String) -> Error) -> Result<T> {
        self.map_err(|e| kind(chain(&e)))
    }
}

/// Return an error of a kind with a formatted message: `fail!(Input, "{name}: empty")`.
macro_rules! fail {
    ($kind:ident, $($arg:tt)+) => {
        return Err($crate::error::Error::$kind(format!($($arg)+)))
    };
}

/// An error of a kind with a formatted message: `error!(Gpu, "no adapter")`.
macro_rules! error {
    ($kind:ident, $($arg:tt)+) => {
        $crate::error::Error::$kind(format!($($arg)+))
    };
}

pub(crate) use {error, fail};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_read_as_anyhow_chains_did() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file");
        let e: Result<()> = Err(io).context("cannot read a.fits");
        let e = e.context("frame 3").unwrap_err();
        assert_eq!(e.to_string(), "frame 3: cannot read a.fits: No such file");
        assert!(
            matches!(&e, Error::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound)
        );
        let e = error!(Input, "{} is empty", "b.png").context("decoding");
        assert_eq!(format!("{e:#}"), "decoding: b.png is empty");
        assert!(matches!(e, Error::Input(_)));
        assert!(std::error::Error::source(&e).is_none());
    }

    #[test]
    fn a_copy_keeps_the_kind_and_the_message() {
        let os = std::io::Error::from_raw_os_error(2);
        let e = Error::Io {
            context: "cannot read a.fits".into(),
            error: os,
        };
        let copy = e.clone();
        assert_eq!(copy.to_string(), e.to_string());
        assert!(
            matches!(&copy, Error::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound)
        );
        let e = error!(Catalog, "no stars");
        assert!(matches!(e.clone(), Error::Catalog(m) if m == "no stars"));
    }
}

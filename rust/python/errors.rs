//! The named exceptions of `boucwen`, all subclasses of `ValueError` (so `except
//! ValueError` catches every one), and the one mapping from the crate's [`Error`].
//!
//! Each [`Error`] variant maps to exactly one exception, in [`value_error`]; the
//! bindings and the Python layer raise the same classes for the same situations they
//! detect themselves (a record's shape, a config option's type, a pickled state).

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::Error;

create_exception!(
    boucwen,
    InvalidParams,
    PyValueError,
    "A model or effect parameter is out of its domain (non-finite, n <= 0, an unknown or missing name, a wrong count); raised before anything is built or changed."
);
create_exception!(
    boucwen,
    InvalidConfig,
    PyValueError,
    "A configuration value is invalid: the sampling interval dt [s], a window length, a tuning option of HorizonConfig/RpemConfig/PaperConfig, a channel count, an option of fit or diagnose."
);
create_exception!(
    boucwen,
    InvalidRecord,
    PyValueError,
    "A record or signal cannot be used: a NaN or infinite sample (rejected; an identifier's state is kept), an array not 1-D or empty, u and x of different lengths, a CSV file or column that cannot be read."
);
create_exception!(
    boucwen,
    CorruptSnapshot,
    PyValueError,
    "Snapshot bytes (a pickled Model, Identifier, Inverse...) are truncated, foreign or corrupt; nothing is built from them."
);
create_exception!(
    boucwen,
    LengthMismatch,
    PyValueError,
    "Two arrays handed to the core that must have the same length do not (creep gains and time constants, a bank frame and the channel count, u and x of push_many)."
);

/// Maps a crate error to its named exception, with the error's one-line message.
pub(crate) fn value_error(err: Error) -> PyErr {
    let msg = err.to_string();
    match err {
        Error::InvalidParameter { .. } => InvalidParams::new_err(msg),
        Error::InvalidConfig { .. } => InvalidConfig::new_err(msg),
        Error::NonFiniteSample { .. } => InvalidRecord::new_err(msg),
        Error::CorruptSnapshot { .. } => CorruptSnapshot::new_err(msg),
        Error::LengthMismatch { .. } => LengthMismatch::new_err(msg),
    }
}

/// Adds the exceptions to the extension module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("InvalidParams", py.get_type::<InvalidParams>())?;
    m.add("InvalidConfig", py.get_type::<InvalidConfig>())?;
    m.add("InvalidRecord", py.get_type::<InvalidRecord>())?;
    m.add("CorruptSnapshot", py.get_type::<CorruptSnapshot>())?;
    m.add("LengthMismatch", py.get_type::<LengthMismatch>())?;
    Ok(())
}

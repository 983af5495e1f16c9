//! Configuration objects: the Python dataclasses `boucwen.RpemConfig` and
//! `boucwen.PaperConfig` mirror [`RpemConfig`] and [`PaperConfig`] field by field.
//!
//! Each Rust config is described once here as a table of named slots; the same table
//! gives the Python defaults (`_config_defaults`), reads a Python config object
//! (any object with those attributes) and writes one back.

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use super::{value_error, InvalidConfig};
use crate::identify::{Decomposition, HorizonConfig, PaperConfig, RpemConfig};

/// One option of a configuration, borrowed from the struct.
pub(crate) enum Slot<'a> {
    Float(&'a mut f64),
    Pair(&'a mut (f64, f64)),
    Count(&'a mut usize),
    Scales(&'a mut [f64; 7]),
    Scales8(&'a mut [f64; 8]),
    Decomposition(&'a mut Decomposition),
}

/// The options of [`RpemConfig`], by their Python names.
pub(crate) fn rpem_slots(c: &mut RpemConfig) -> Vec<(&'static str, Slot<'_>)> {
    vec![
        ("forgetting", Slot::Float(&mut c.forgetting)),
        ("memory_travel_v", Slot::Float(&mut c.memory_travel_v)),
        ("p0", Slot::Float(&mut c.p0)),
        ("offset_walk_um", Slot::Float(&mut c.offset_walk_um)),
        ("p0_effects", Slot::Float(&mut c.p0_effects)),
        ("noise_um2", Slot::Float(&mut c.noise_um2)),
        ("noise_memory_samples", Slot::Float(&mut c.noise_memory_samples)),
        ("max_trace", Slot::Float(&mut c.max_trace)),
        ("max_step", Slot::Float(&mut c.max_step)),
        ("max_offset_step_um", Slot::Float(&mut c.max_offset_step_um)),
        ("n_bounds", Slot::Pair(&mut c.n_bounds)),
        ("margin", Slot::Float(&mut c.margin)),
        ("scales", Slot::Scales(&mut c.scales)),
        ("creep_gain_scale_um_per_v", Slot::Float(&mut c.creep_gain_scale_um_per_v)),
        ("creep_gain_max_um_per_v", Slot::Float(&mut c.creep_gain_max_um_per_v)),
        ("fc_bounds_hz", Slot::Pair(&mut c.fc_bounds_hz)),
    ]
}

/// The options of [`HorizonConfig`], by their Python names.
pub(crate) fn horizon_slots(c: &mut HorizonConfig) -> Vec<(&'static str, Slot<'_>)> {
    vec![
        ("memory_travel_v", Slot::Float(&mut c.memory_travel_v)),
        ("recent_factor", Slot::Float(&mut c.recent_factor)),
        ("max_window", Slot::Count(&mut c.max_window)),
        ("samples_per_push", Slot::Count(&mut c.samples_per_push)),
        ("min_pass_fraction", Slot::Float(&mut c.min_pass_fraction)),
        ("ridge", Slot::Float(&mut c.ridge)),
        ("damping", Slot::Float(&mut c.damping)),
        ("max_step", Slot::Float(&mut c.max_step)),
        ("n_bounds", Slot::Pair(&mut c.n_bounds)),
        ("fc_bounds_hz", Slot::Pair(&mut c.fc_bounds_hz)),
        ("margin", Slot::Float(&mut c.margin)),
        ("scales", Slot::Scales8(&mut c.scales)),
    ]
}

/// The options of [`PaperConfig`] but the window length (an argument of its own).
pub(crate) fn paper_slots(c: &mut PaperConfig) -> Vec<(&'static str, Slot<'_>)> {
    vec![
        ("decomposition", Slot::Decomposition(&mut c.decomposition)),
        ("h_zero_frac", Slot::Float(&mut c.h_zero_frac)),
        ("rate_frac", Slot::Float(&mut c.rate_frac)),
        ("min_points", Slot::Count(&mut c.min_points)),
        ("rank_tol", Slot::Float(&mut c.rank_tol)),
        ("min_log_spread", Slot::Float(&mut c.min_log_spread)),
        ("min_arg_frac", Slot::Float(&mut c.min_arg_frac)),
        ("noise_gate", Slot::Float(&mut c.noise_gate)),
        ("derivative_phase", Slot::Float(&mut c.derivative_phase)),
        ("max_half_width", Slot::Count(&mut c.max_half_width)),
        ("min_delta_t", Slot::Float(&mut c.min_delta_t)),
        ("min_r2", Slot::Float(&mut c.min_r2)),
        ("min_line_t", Slot::Float(&mut c.min_line_t)),
        ("min_u_std_v", Slot::Float(&mut c.min_u_std_v)),
        ("n_bounds", Slot::Pair(&mut c.n_bounds)),
        ("max_hysteresis_gain", Slot::Float(&mut c.max_hysteresis_gain)),
        ("max_delta_ratio", Slot::Float(&mut c.max_delta_ratio)),
        ("output_gate", Slot::Float(&mut c.output_gate)),
        ("min_stroke_frac", Slot::Float(&mut c.min_stroke_frac)),
        ("fit_every", Slot::Float(&mut c.fit_every)),
        ("fit_iterations", Slot::Count(&mut c.fit_iterations)),
        ("min_fit_t", Slot::Float(&mut c.min_fit_t)),
        ("max_misfit", Slot::Float(&mut c.max_misfit)),
    ]
}

fn type_error(name: &str, what: &str) -> PyErr {
    PyTypeError::new_err(format!("config option {name} must be {what}"))
}

/// Sets every slot from the attribute of `obj` with its name.
pub(crate) fn read_slots(obj: &Bound<'_, PyAny>, slots: Vec<(&'static str, Slot<'_>)>) -> PyResult<()> {
    for (name, slot) in slots {
        let v = obj.getattr(name).map_err(|_| PyTypeError::new_err(format!("config has no option {name}")))?;
        match slot {
            Slot::Float(f) => *f = v.extract().map_err(|_| type_error(name, "a number"))?,
            Slot::Pair(p) => *p = v.extract().map_err(|_| type_error(name, "a pair of numbers"))?,
            Slot::Count(n) => {
                let k: i64 = v.extract().map_err(|_| type_error(name, "an integer"))?;
                *n = usize::try_from(k)
                    .map_err(|_| InvalidConfig::new_err(format!("invalid {name} = {k}: must be >= 0")))?;
            }
            Slot::Scales(s) => {
                let vs: Vec<f64> = v.extract().map_err(|_| type_error(name, "a sequence of 7 numbers"))?;
                *s = vs.try_into().map_err(|_| type_error(name, "a sequence of 7 numbers"))?;
            }
            Slot::Scales8(s) => {
                let vs: Vec<f64> = v.extract().map_err(|_| type_error(name, "a sequence of 8 numbers"))?;
                *s = vs.try_into().map_err(|_| type_error(name, "a sequence of 8 numbers"))?;
            }
            Slot::Decomposition(d) => {
                let text: String = v.extract().map_err(|_| type_error(name, "\"model\" or \"line\""))?;
                *d = match text.as_str() {
                    "model" => Decomposition::Model,
                    "line" => Decomposition::Line,
                    other => {
                        return Err(InvalidConfig::new_err(format!(
                            "invalid decomposition = {other:?}: expected \"model\" or \"line\""
                        )))
                    }
                };
            }
        }
    }
    Ok(())
}

/// The slots as a dict of Python values.
pub(crate) fn slots_dict<'py>(py: Python<'py>, slots: Vec<(&'static str, Slot<'_>)>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (name, slot) in slots {
        match slot {
            Slot::Float(f) => d.set_item(name, *f)?,
            Slot::Pair(p) => d.set_item(name, *p)?,
            Slot::Count(n) => d.set_item(name, *n)?,
            Slot::Scales(s) => d.set_item(name, s.to_vec())?,
            Slot::Scales8(s) => d.set_item(name, s.to_vec())?,
            Slot::Decomposition(x) => d.set_item(
                name,
                match x {
                    Decomposition::Model => "model",
                    Decomposition::Line => "line",
                },
            )?,
        }
    }
    Ok(d)
}

/// The slots as the frozen Python config object of class `class` (`"HorizonConfig"`,
/// `"RpemConfig"` or `"PaperConfig"` of `boucwen.config`).
pub(crate) fn config_object<'py>(
    py: Python<'py>,
    class: &str,
    slots: Vec<(&'static str, Slot<'_>)>,
) -> PyResult<Bound<'py, PyAny>> {
    let options = slots_dict(py, slots)?;
    py.import("boucwen.config")?.getattr(class)?.call((), Some(&options))
}

/// The rpem configuration held by a Python config object (`None`: `default`).
pub(crate) fn rpem_config(obj: Option<&Bound<'_, PyAny>>, default: RpemConfig) -> PyResult<RpemConfig> {
    let mut cfg = default;
    if let Some(obj) = obj {
        read_slots(obj, rpem_slots(&mut cfg))?;
    }
    cfg.validate().map_err(value_error)?;
    Ok(cfg)
}

/// The horizon configuration held by a Python config object (`None`: the defaults).
pub(crate) fn horizon_config(obj: Option<&Bound<'_, PyAny>>) -> PyResult<HorizonConfig> {
    let mut cfg = HorizonConfig::default();
    if let Some(obj) = obj {
        read_slots(obj, horizon_slots(&mut cfg))?;
    }
    cfg.validate().map_err(value_error)?;
    Ok(cfg)
}

/// The paper configuration held by a Python config object, with window `window`
/// \[samples\] (`InvalidConfig` outside `PaperConfig::MIN_WINDOW..=MAX_WINDOW`).
pub(crate) fn paper_config(obj: Option<&Bound<'_, PyAny>>, window: i64) -> PyResult<PaperConfig> {
    let range = PaperConfig::MIN_WINDOW..=PaperConfig::MAX_WINDOW;
    let window = usize::try_from(window).ok().filter(|w| range.contains(w)).ok_or_else(|| {
        InvalidConfig::new_err(format!(
            "invalid window = {window}: the window holds {} to {} samples",
            PaperConfig::MIN_WINDOW,
            PaperConfig::MAX_WINDOW
        ))
    })?;
    let mut cfg = PaperConfig::with_window(window);
    if let Some(obj) = obj {
        read_slots(obj, paper_slots(&mut cfg))?;
    }
    cfg.validate().map_err(value_error)?;
    Ok(cfg)
}

/// Default options of a method ("horizon", "rpem" or "paper") as a dict (the Python config
/// dataclasses take their defaults from here).
#[pyfunction]
pub(crate) fn _config_defaults<'py>(py: Python<'py>, method: &str) -> PyResult<Bound<'py, PyDict>> {
    match method {
        "rpem" => slots_dict(py, rpem_slots(&mut RpemConfig::default())),
        "horizon" => slots_dict(py, horizon_slots(&mut HorizonConfig::default())),
        "paper" => slots_dict(py, paper_slots(&mut PaperConfig::with_window(PaperConfig::MIN_WINDOW))),
        other => Err(PyValueError::new_err(format!(
            "invalid method = {other:?}: expected \"horizon\", \"rpem\" or \"paper\""
        ))),
    }
}

/// Validates a config object of a method; ValueError naming the offending option.
#[pyfunction]
pub(crate) fn _validate_config(method: &str, config: &Bound<'_, PyAny>) -> PyResult<()> {
    match method {
        "rpem" => rpem_config(Some(config), RpemConfig::default()).map(|_| ()),
        "horizon" => horizon_config(Some(config)).map(|_| ()),
        // min_points is checked against the window when the identifier is built.
        "paper" => paper_config(Some(config), PaperConfig::MAX_WINDOW as i64).map(|_| ()),
        other => Err(PyValueError::new_err(format!(
            "invalid method = {other:?}: expected \"horizon\", \"rpem\" or \"paper\""
        ))),
    }
}

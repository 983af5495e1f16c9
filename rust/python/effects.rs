//! `boucwen.EffectSet` and `boucwen.simulate_extended`: conversions only.

use numpy::PyArray1;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use super::params::PyParams;
use super::{samples, value_error};
use crate::effects::{Creep, Delay, Drift, EffectSet, InputLag, Resonance};

/// Which effects surround the base model, with their parameters.
///
/// Each argument is ``None`` (effect absent) or a dict of the effect's parameters:
///
/// - ``creep={"tau_s": [τ_i …], "gain_um_per_v": [g_i …]}``: τ_i·ċ_i = g_i·u_a − c_i,
///   x += Σ c_i (τ_i \[s\] > 0, g_i \[µm/V\]);
/// - ``input_lag={"fc_hz": fc}``: first-order lag of the voltage, corner fc \[Hz\] > 0;
/// - ``resonance={"fn_hz": fn, "zeta": ζ}``: z̈ + 2ζω·ż + ω²·z = ω²·y between the stack
///   and the sensor, ω = 2π·fn (fn \[Hz\] > 0 and below Nyquist, ζ > 0);
/// - ``drift={"rate_um_per_s": r}``: x += r·t, t \[s\] from the first sample;
/// - ``delay={"samples": d}``: the sensor reads x[k − d], d ≥ 0 whole samples.
///
/// Immutable, comparable, picklable; ``to_dict``/``from_dict`` round-trip. The typed
/// form (``InputLag(fc_hz=650.0)``, …) is in :mod:`boucwen.effects`:
/// ``boucwen.effect_set(*effects)`` builds an ``EffectSet``, ``boucwen.effects_of(s)``
/// gives its effects back.
#[pyclass(name = "EffectSet", module = "boucwen", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyEffectSet {
    pub inner: EffectSet,
}

fn get_f64(d: &Bound<'_, PyDict>, effect: &str, key: &str) -> PyResult<f64> {
    let item = d.get_item(key)?.ok_or_else(|| PyValueError::new_err(format!("{effect}: missing parameter {key:?}")))?;
    if item.is_instance_of::<pyo3::types::PyBool>() {
        return Err(PyTypeError::new_err(format!("{effect}.{key} must be a number, got a bool")));
    }
    item.extract::<f64>()
        .map_err(|_| PyTypeError::new_err(format!("{effect}.{key} must be a number, got {}", type_name(&item))))
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
}

fn as_dict<'py>(obj: &Bound<'py, PyAny>, effect: &str, keys: &[&str]) -> PyResult<Bound<'py, PyDict>> {
    let d = obj.cast::<PyDict>().map_err(|_| {
        PyTypeError::new_err(format!("{effect} must be None or a dict with keys {keys:?}, got {}", type_name(obj)))
    })?;
    for key in d.keys() {
        let key: String = key.str()?.to_string();
        if !keys.contains(&key.as_str()) {
            return Err(PyValueError::new_err(format!("{effect}: unknown parameter {key:?}; expected {keys:?}")));
        }
    }
    Ok(d.clone())
}

fn some<'py>(o: Option<&Bound<'py, PyAny>>) -> Option<Bound<'py, PyAny>> {
    o.filter(|o| !o.is_none()).cloned()
}

fn parse(
    creep: Option<&Bound<'_, PyAny>>,
    input_lag: Option<&Bound<'_, PyAny>>,
    resonance: Option<&Bound<'_, PyAny>>,
    drift: Option<&Bound<'_, PyAny>>,
    delay: Option<&Bound<'_, PyAny>>,
) -> PyResult<EffectSet> {
    let mut set = EffectSet::none();
    if let Some(o) = some(creep) {
        let d = as_dict(&o, "creep", &["tau_s", "gain_um_per_v"])?;
        let field = |key: &str| -> PyResult<Vec<f64>> {
            let item =
                d.get_item(key)?.ok_or_else(|| PyValueError::new_err(format!("creep: missing parameter {key:?}")))?;
            samples(&item, &format!("creep.{key}"))
        };
        set.creep = Some(Creep { tau_s: field("tau_s")?, gain_um_per_v: field("gain_um_per_v")? });
    }
    if let Some(o) = some(input_lag) {
        let d = as_dict(&o, "input_lag", &["fc_hz"])?;
        set.input_lag = Some(InputLag { fc_hz: get_f64(&d, "input_lag", "fc_hz")? });
    }
    if let Some(o) = some(resonance) {
        let d = as_dict(&o, "resonance", &["fn_hz", "zeta"])?;
        set.resonance =
            Some(Resonance { fn_hz: get_f64(&d, "resonance", "fn_hz")?, zeta: get_f64(&d, "resonance", "zeta")? });
    }
    if let Some(o) = some(drift) {
        let d = as_dict(&o, "drift", &["rate_um_per_s"])?;
        set.drift = Some(Drift { rate_um_per_s: get_f64(&d, "drift", "rate_um_per_s")? });
    }
    if let Some(o) = some(delay) {
        let d = as_dict(&o, "delay", &["samples"])?;
        let item =
            d.get_item("samples")?.ok_or_else(|| PyValueError::new_err("delay: missing parameter \"samples\""))?;
        if item.is_instance_of::<pyo3::types::PyBool>() {
            return Err(PyTypeError::new_err("delay.samples must be an integer, got a bool"));
        }
        let v: i64 = item
            .extract()
            .map_err(|_| PyTypeError::new_err(format!("delay.samples must be an integer, got {}", type_name(&item))))?;
        if v < 0 {
            return Err(PyValueError::new_err(format!("invalid parameter delay.samples = {v}: must be >= 0")));
        }
        set.delay = Some(Delay { samples: v as usize });
    }
    set.validate().map_err(value_error)?;
    Ok(set)
}

#[pymethods]
impl PyEffectSet {
    #[new]
    #[pyo3(signature = (*, creep = None, input_lag = None, resonance = None, drift = None, delay = None))]
    fn new(
        creep: Option<&Bound<'_, PyAny>>,
        input_lag: Option<&Bound<'_, PyAny>>,
        resonance: Option<&Bound<'_, PyAny>>,
        drift: Option<&Bound<'_, PyAny>>,
        delay: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        parse(creep, input_lag, resonance, drift, delay).map(|inner| PyEffectSet { inner })
    }

    /// The vocabulary of effect names, in signal-chain order.
    #[classattr]
    fn vocabulary() -> Vec<&'static str> {
        EffectSet::NAMES.to_vec()
    }

    /// Names of the effects present, in vocabulary order.
    #[getter]
    fn names(&self) -> Vec<&'static str> {
        self.inner.names()
    }

    fn __len__(&self) -> usize {
        self.inner.names().len()
    }

    fn __contains__(&self, name: &str) -> bool {
        self.inner.names().contains(&name)
    }

    /// ``{effect name: {parameter: value}}`` for the effects present.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        let e = &self.inner;
        if let Some(c) = &e.creep {
            let d = PyDict::new(py);
            d.set_item("tau_s", c.tau_s.clone())?;
            d.set_item("gain_um_per_v", c.gain_um_per_v.clone())?;
            out.set_item("creep", d)?;
        }
        if let Some(l) = &e.input_lag {
            let d = PyDict::new(py);
            d.set_item("fc_hz", l.fc_hz)?;
            out.set_item("input_lag", d)?;
        }
        if let Some(r) = &e.resonance {
            let d = PyDict::new(py);
            d.set_item("fn_hz", r.fn_hz)?;
            d.set_item("zeta", r.zeta)?;
            out.set_item("resonance", d)?;
        }
        if let Some(r) = &e.drift {
            let d = PyDict::new(py);
            d.set_item("rate_um_per_s", r.rate_um_per_s)?;
            out.set_item("drift", d)?;
        }
        if let Some(r) = &e.delay {
            let d = PyDict::new(py);
            d.set_item("samples", r.samples)?;
            out.set_item("delay", d)?;
        }
        Ok(out)
    }

    /// Inverse of ``to_dict``; keys must be effect names.
    #[staticmethod]
    fn from_dict(d: &Bound<'_, PyAny>) -> PyResult<Self> {
        let d = d
            .cast::<PyDict>()
            .map_err(|_| PyTypeError::new_err(format!("EffectSet.from_dict needs a dict, got {}", type_name(d))))?;
        for key in d.keys() {
            let key: String = key.str()?.to_string();
            if !EffectSet::NAMES.contains(&key.as_str()) {
                return Err(PyValueError::new_err(format!(
                    "unknown effect {key:?}; expected one of {:?}",
                    EffectSet::NAMES
                )));
            }
        }
        let get = |k: &str| d.get_item(k);
        parse(
            get("creep")?.as_ref(),
            get("input_lag")?.as_ref(),
            get("resonance")?.as_ref(),
            get("drift")?.as_ref(),
            get("delay")?.as_ref(),
        )
        .map(|inner| PyEffectSet { inner })
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let d = self.to_dict(py)?;
        let parts: Vec<String> =
            d.iter().map(|(k, v)| Ok(format!("{}={}", k.str()?, v.repr()?))).collect::<PyResult<_>>()?;
        Ok(format!("EffectSet({})", parts.join(", ")))
    }

    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let py = slf.py();
        let from_dict = slf.get_type().getattr("from_dict")?;
        let args = PyTuple::new(py, [slf.get().to_dict(py)?])?;
        Ok((from_dict, args))
    }
}

/// Simulates the base model with effects over a record.
///
/// ``params``: the base :class:`Params`; ``effects``: an :class:`EffectSet` (or None
/// for none); ``u``: commanded voltage \[V\], piecewise linear between samples ``dt``
/// \[s\] apart; ``h0``: initial hysteresis state \[µm\]. Returns x \[µm\] as the sensor
/// reads it. The chain is u → input_lag → (Bouc–Wen + creep) → resonance → + drift →
/// delay; everything starts at rest with the first sample. The GIL is released while
/// it runs.
#[pyfunction]
#[pyo3(signature = (params, effects, u, dt, h0 = 0.0))]
pub fn simulate_extended<'py>(
    py: Python<'py>,
    params: &PyParams,
    effects: Option<&PyEffectSet>,
    u: &Bound<'py, PyAny>,
    dt: f64,
    h0: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let u = samples(u, "u")?;
    let p = params.inner;
    let e = effects.map(|e| e.inner.clone()).unwrap_or_default();
    let x = py.detach(move || crate::effects::simulate_extended(&p, &e, &u, dt, h0)).map_err(value_error)?;
    Ok(PyArray1::from_vec(py, x))
}

//! `boucwen.EffectSet`, `boucwen.simulate_extended` and its Jacobian: conversions only.

use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use super::extended_state::PyExtendedState;
use super::params::PyParams;
use super::reconstruction::reconstruction;
use super::{samples, value_error, InvalidConfig, InvalidParams};
use crate::effects::jacobian::Jacobian;
use crate::effects::{
    BetweenSamples, Creep, Delay, Drift, EffectSet, Electrostriction, GainDrift, InputLag, Pickup, Resonance,
    Resonance2, Saturation,
};

/// Which effects surround the base model, with their parameters.
///
/// Each argument is ``None`` (effect absent) or a dict of the effect's parameters:
///
/// - ``creep={"tau_s": [τ_i …], "gain_um_per_v": [g_i …]}``: τ_i·ċ_i = g_i·u_a − c_i,
///   x += Σ c_i (τ_i \[s\] > 0, g_i \[µm/V\]);
/// - ``input_lag={"fc_hz": fc}``: first-order lag of the voltage, corner fc \[Hz\] > 0;
/// - ``resonance={"fn_hz": fn, "zeta": ζ}``: z̈ + 2ζω·ż + ω²·z = ω²·y between the stack
///   and the sensor, ω = 2π·fn (fn \[Hz\] > 0 and below Nyquist, ζ > 0);
/// - ``gain_drift={"rate_per_s": r}``: kv(t) = kv·(1 + r·t), r \[1/s\];
/// - ``electrostriction={"epsilon_per_um": ε}``: s = kv·u_a + h becomes s + ε·s²,
///   ε \[1/µm\];
/// - ``resonance2={"fn_hz": fn, "zeta": ζ}``: a second mode in series after
///   ``resonance`` (same form and bounds);
/// - ``drift={"rate_um_per_s": r}``: x += r·t, t \[s\] from the first sample;
/// - ``delay={"samples": d}``: the sensor reads x[k − d], d ≥ 0 whole samples;
/// - ``pickup={"line_hz": f, "sin_um": [a_k …], "cos_um": [b_k …]}``:
///   x += Σ_k a_k·sin(2π·k·f·t) + b_k·cos(2π·k·f·t), k = 1 … K ≤ 8, f \[Hz\],
///   a_k, b_k \[µm\];
/// - ``saturation={"min_um": lo, "max_um": hi}``: x = clip(x, lo, hi) \[µm\];
/// - ``between_samples={"input": "hold" | "linear" | "bandlimited"}``: what the command
///   does between samples (the measurement chain's input end; absent: a straight line).
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
    let item =
        d.get_item(key)?.ok_or_else(|| InvalidParams::new_err(format!("{effect}: missing parameter {key:?}")))?;
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
            return Err(InvalidParams::new_err(format!("{effect}: unknown parameter {key:?}; expected {keys:?}")));
        }
    }
    Ok(d.clone())
}

/// The value given for each effect (None: absent), in vocabulary order.
type Given<'py> = [Option<Bound<'py, PyAny>>; 11];

fn float_list(d: &Bound<'_, PyDict>, effect: &str, key: &str) -> PyResult<Vec<f64>> {
    let item =
        d.get_item(key)?.ok_or_else(|| InvalidParams::new_err(format!("{effect}: missing parameter {key:?}")))?;
    samples(&item, &format!("{effect}.{key}"))
}

fn parse(given: &Given<'_>) -> PyResult<EffectSet> {
    let [creep, input_lag, gain_drift, electrostriction, resonance, resonance2, drift, delay, pickup, saturation, between_samples] =
        given.each_ref().map(|o| o.as_ref().filter(|o| !o.is_none()));
    let mut set = EffectSet::none();
    if let Some(o) = creep {
        let d = as_dict(o, "creep", &["tau_s", "gain_um_per_v"])?;
        set.creep = Some(Creep {
            tau_s: float_list(&d, "creep", "tau_s")?,
            gain_um_per_v: float_list(&d, "creep", "gain_um_per_v")?,
        });
    }
    if let Some(o) = input_lag {
        let d = as_dict(o, "input_lag", &["fc_hz"])?;
        set.input_lag = Some(InputLag { fc_hz: get_f64(&d, "input_lag", "fc_hz")? });
    }
    if let Some(o) = gain_drift {
        let d = as_dict(o, "gain_drift", &["rate_per_s"])?;
        set.gain_drift = Some(GainDrift { rate_per_s: get_f64(&d, "gain_drift", "rate_per_s")? });
    }
    if let Some(o) = electrostriction {
        let d = as_dict(o, "electrostriction", &["epsilon_per_um"])?;
        set.electrostriction =
            Some(Electrostriction { epsilon_per_um: get_f64(&d, "electrostriction", "epsilon_per_um")? });
    }
    if let Some(o) = resonance {
        let d = as_dict(o, "resonance", &["fn_hz", "zeta"])?;
        set.resonance =
            Some(Resonance { fn_hz: get_f64(&d, "resonance", "fn_hz")?, zeta: get_f64(&d, "resonance", "zeta")? });
    }
    if let Some(o) = resonance2 {
        let d = as_dict(o, "resonance2", &["fn_hz", "zeta"])?;
        set.resonance2 =
            Some(Resonance2 { fn_hz: get_f64(&d, "resonance2", "fn_hz")?, zeta: get_f64(&d, "resonance2", "zeta")? });
    }
    if let Some(o) = drift {
        let d = as_dict(o, "drift", &["rate_um_per_s"])?;
        set.drift = Some(Drift { rate_um_per_s: get_f64(&d, "drift", "rate_um_per_s")? });
    }
    if let Some(o) = delay {
        let d = as_dict(o, "delay", &["samples"])?;
        let item =
            d.get_item("samples")?.ok_or_else(|| InvalidParams::new_err("delay: missing parameter \"samples\""))?;
        if item.is_instance_of::<pyo3::types::PyBool>() {
            return Err(PyTypeError::new_err("delay.samples must be an integer, got a bool"));
        }
        let v: i64 = item
            .extract()
            .map_err(|_| PyTypeError::new_err(format!("delay.samples must be an integer, got {}", type_name(&item))))?;
        if v < 0 {
            return Err(InvalidParams::new_err(format!("invalid parameter delay.samples = {v}: must be >= 0")));
        }
        set.delay = Some(Delay { samples: v as usize });
    }
    if let Some(o) = pickup {
        let d = as_dict(o, "pickup", &["line_hz", "sin_um", "cos_um"])?;
        set.pickup = Some(Pickup {
            line_hz: get_f64(&d, "pickup", "line_hz")?,
            sin_um: float_list(&d, "pickup", "sin_um")?,
            cos_um: float_list(&d, "pickup", "cos_um")?,
        });
    }
    if let Some(o) = saturation {
        let d = as_dict(o, "saturation", &["min_um", "max_um"])?;
        set.saturation = Some(Saturation {
            min_um: get_f64(&d, "saturation", "min_um")?,
            max_um: get_f64(&d, "saturation", "max_um")?,
        });
    }
    if let Some(o) = between_samples {
        let d = as_dict(o, "between_samples", &["input"])?;
        let item = d
            .get_item("input")?
            .ok_or_else(|| InvalidParams::new_err("between_samples: missing parameter \"input\""))?;
        let name: String = item.extract().map_err(|_| {
            PyTypeError::new_err(format!("between_samples.input must be a string, got {}", type_name(&item)))
        })?;
        set.between_samples = Some(BetweenSamples { input: reconstruction(&name)? });
    }
    set.validate().map_err(value_error)?;
    Ok(set)
}

#[pymethods]
impl PyEffectSet {
    #[new]
    #[pyo3(signature = (
        *, creep = None, input_lag = None, gain_drift = None, electrostriction = None, resonance = None,
        resonance2 = None, drift = None, delay = None, pickup = None, saturation = None, between_samples = None
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new<'py>(
        creep: Option<Bound<'py, PyAny>>,
        input_lag: Option<Bound<'py, PyAny>>,
        gain_drift: Option<Bound<'py, PyAny>>,
        electrostriction: Option<Bound<'py, PyAny>>,
        resonance: Option<Bound<'py, PyAny>>,
        resonance2: Option<Bound<'py, PyAny>>,
        drift: Option<Bound<'py, PyAny>>,
        delay: Option<Bound<'py, PyAny>>,
        pickup: Option<Bound<'py, PyAny>>,
        saturation: Option<Bound<'py, PyAny>>,
        between_samples: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        let given = [
            creep,
            input_lag,
            gain_drift,
            electrostriction,
            resonance,
            resonance2,
            drift,
            delay,
            pickup,
            saturation,
            between_samples,
        ];
        parse(&given).map(|inner| PyEffectSet { inner })
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
        if let Some(g) = &e.gain_drift {
            let d = PyDict::new(py);
            d.set_item("rate_per_s", g.rate_per_s)?;
            out.set_item("gain_drift", d)?;
        }
        if let Some(g) = &e.electrostriction {
            let d = PyDict::new(py);
            d.set_item("epsilon_per_um", g.epsilon_per_um)?;
            out.set_item("electrostriction", d)?;
        }
        for (name, mode) in [
            ("resonance", e.resonance.map(|r| (r.fn_hz, r.zeta))),
            ("resonance2", e.resonance2.map(|r| (r.fn_hz, r.zeta))),
        ] {
            if let Some((fn_hz, zeta)) = mode {
                let d = PyDict::new(py);
                d.set_item("fn_hz", fn_hz)?;
                d.set_item("zeta", zeta)?;
                out.set_item(name, d)?;
            }
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
        if let Some(p) = &e.pickup {
            let d = PyDict::new(py);
            d.set_item("line_hz", p.line_hz)?;
            d.set_item("sin_um", p.sin_um.clone())?;
            d.set_item("cos_um", p.cos_um.clone())?;
            out.set_item("pickup", d)?;
        }
        if let Some(s) = &e.saturation {
            let d = PyDict::new(py);
            d.set_item("min_um", s.min_um)?;
            d.set_item("max_um", s.max_um)?;
            out.set_item("saturation", d)?;
        }
        if let Some(b) = &e.between_samples {
            let d = PyDict::new(py);
            d.set_item("input", b.input.name())?;
            out.set_item("between_samples", d)?;
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
                return Err(InvalidParams::new_err(format!(
                    "unknown effect {key:?}; expected one of {:?}",
                    EffectSet::NAMES
                )));
            }
        }
        let mut given: Given<'_> = Default::default();
        for (slot, name) in given.iter_mut().zip(EffectSet::NAMES) {
            *slot = d.get_item(name)?;
        }
        parse(&given).map(|inner| PyEffectSet { inner })
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
/// reads it. The chain is u → input_lag → (Bouc–Wen with gain_drift, electrostriction,
/// + creep) → resonance → resonance2 → + drift → delay → + pickup → saturation;
/// everything starts at rest with the first sample.
///
/// With ``state`` (an :class:`ExtendedState`), the chain continues from it instead
/// (``h0`` is then the state's) and the call returns ``(x, final_state)``, as
/// ``scipy.signal.lfilter`` does with ``zi``: a record simulated in pieces, each from
/// the state the previous one returned, is the record simulated in one call, bit for
/// bit. ``ExtendedState(h0)`` starts a record. The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (params, effects, u, dt, h0 = 0.0, *, state = None))]
pub fn simulate_extended<'py>(
    py: Python<'py>,
    params: &PyParams,
    effects: Option<&PyEffectSet>,
    u: &Bound<'py, PyAny>,
    dt: f64,
    h0: f64,
    state: Option<&PyExtendedState>,
) -> PyResult<Bound<'py, PyAny>> {
    let (p, e, u) = chain_inputs(params, effects, u)?;
    let Some(state) = state else {
        let x = py.detach(move || crate::effects::simulate_extended(&p, &e, &u, dt, h0)).map_err(value_error)?;
        return Ok(PyArray1::from_vec(py, x).into_any());
    };
    if h0 != 0.0 {
        return Err(InvalidConfig::new_err(format!(
            "h0 = {h0} and state are exclusive: the state holds h (ExtendedState(h0) starts a record)"
        )));
    }
    let start = state.inner.clone();
    let (x, end) =
        py.detach(move || crate::effects::simulate_extended_from(&p, &e, &u, dt, &start)).map_err(value_error)?;
    let end = Bound::new(py, PyExtendedState { inner: end })?;
    Ok((PyArray1::from_vec(py, x), end).into_pyobject(py)?.into_any())
}

/// :func:`simulate_extended` with the Jacobian of x with respect to the unknowns of a
/// fit, in one pass (forward-mode automatic differentiation through the same
/// integrator).
///
/// Returns ``(x, jac)``: x \[µm\] as :func:`simulate_extended` gives it (the same
/// numbers) and ``jac[k, j]`` = ∂x\[k\]/∂θ_j, one column per unknown θ_j: kv, x0, A, β,
/// γ, n, δ, h0, then for each effect present in signal-chain order the creep gains, the
/// input lag's ln fc, the gain_drift rate, the electrostriction ε, the resonance's
/// ln fn and ln ζ, the second resonance's ln fn and ln ζ, the drift rate, the pickup's
/// sine then cosine amplitudes, the saturation's min and max (the creep time constants
/// and the delay are fixed). ``h0`` \[µm\] is not optional: it is an unknown too. The
/// GIL is released while it runs.
#[pyfunction]
pub fn simulate_extended_with_jacobian<'py>(
    py: Python<'py>,
    params: &PyParams,
    effects: Option<&PyEffectSet>,
    u: &Bound<'py, PyAny>,
    dt: f64,
    h0: f64,
) -> PyResult<OutputAndJacobian<'py>> {
    let (p, e, u) = chain_inputs(params, effects, u)?;
    let jac = py
        .detach(move || crate::effects::jacobian::simulate_extended_with_jacobian(&p, &e, &u, dt, h0))
        .map_err(value_error)?;
    arrays(py, jac)
}

/// The parameters, the effects (none for `None`) and a copy of the voltage samples.
fn chain_inputs(
    params: &PyParams,
    effects: Option<&PyEffectSet>,
    u: &Bound<'_, PyAny>,
) -> PyResult<(crate::Params, EffectSet, Vec<f64>)> {
    Ok((params.inner, effects.map(|e| e.inner.clone()).unwrap_or_default(), samples(u, "u")?))
}

/// x \[µm\] and its Jacobian, one row per sample, as NumPy arrays.
pub(crate) type OutputAndJacobian<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// The arrays of a [`Jacobian`].
fn arrays(py: Python<'_>, jac: Jacobian) -> PyResult<OutputAndJacobian<'_>> {
    let rows = jac.x.len();
    let values = PyArray1::from_vec(py, jac.values).reshape([rows, jac.columns])?;
    Ok((PyArray1::from_vec(py, jac.x), values))
}

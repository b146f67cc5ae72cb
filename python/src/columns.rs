//! Numbers across the boundary: f64 columns travel as little-endian bytes
//! (`numpy.frombuffer` reads them whole; a list of Python floats would cost
//! an object per sample on a capture of millions).

use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use hammer_trace::trace::Trace;

/// The f64 values of little-endian `bytes` (a trailing partial value is
/// ignored; the Python layer passes whole float64 arrays).
pub fn from_le_bytes(bytes: &[u8]) -> Vec<f64> {
    bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("chunks of 8")))
        .collect()
}

fn le_bytes<'py>(py: Python<'py>, values: Vec<f64>) -> Bound<'py, PyBytes> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    PyBytes::new(py, &bytes)
}

/// A trace's columns by their CSV names (`t_s`, `p_rear_pa`, `p_front_pa`,
/// `accel_mps2`, then any further column), each as little-endian f64 bytes.
/// Takes the trace whole and lets each column go once it is copied, so a
/// long run costs about one copy of the table, not two.
pub fn trace_columns(py: Python<'_>, trace: Trace) -> PyResult<Py<PyDict>> {
    let d = PyDict::new(py);
    d.set_item("t_s", le_bytes(py, trace.t_s))?;
    d.set_item("p_rear_pa", le_bytes(py, trace.p_rear_pa))?;
    d.set_item("p_front_pa", le_bytes(py, trace.p_front_pa))?;
    d.set_item("accel_mps2", le_bytes(py, trace.accel_mps2))?;
    for (name, values) in trace.extra {
        d.set_item(name, le_bytes(py, values))?;
    }
    Ok(d.unbind())
}

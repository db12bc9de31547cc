//! Python bindings of rangeseg (the `rangeseg._rangeseg` extension module): cameras, configurations, reading
//! depth files and segmenting numpy arrays, with the GIL released while the pipeline runs.
//!
//! The pure-Python package `rangeseg` (`python/rangeseg/`) wraps this module: it turns configuration dicts into
//! [`PyConfig`]s and the plane columns into a numpy structured array.

use numpy::ndarray::{Array1, Array2};
use numpy::{PyArray1, PyArray2, PyReadonlyArray2, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rangeimage::{AbwCalibration, Camera, Grid, RangeImage};
use rangeseg::Config;
use std::path::{Path, PathBuf};

create_exception!(rangeseg, RangesegError, PyException, "Base class of rangeseg's errors.");
create_exception!(rangeseg, ReadError, RangesegError, "A depth file could not be read (the CLI's message).");
create_exception!(
    rangeseg,
    ConfigError,
    RangesegError,
    "A configuration could not be used (the CLI's message)."
);

/// The message the CLI prints after `error: ` for this error: its text and its sources', joined by `: `.
fn cli_message(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(c) = src {
        s.push_str(": ");
        s.push_str(&c.to_string());
        src = c.source();
    }
    s
}

fn read_err(e: rangeio::ReadError) -> PyErr {
    ReadError::new_err(cli_message(&e))
}

fn config_err(e: rangeseg::ConfigError) -> PyErr {
    ConfigError::new_err(cli_message(&e))
}

/// A pinhole depth camera: `Z = value · depth_scale`, `X = (x − cx)·Z/fx`, `Y = (y − cy)·Z/fy`.
#[pyclass(frozen, eq, module = "rangeseg", name = "Pinhole")]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PyPinhole {
    /// Focal length along x, in pixels.
    #[pyo3(get)]
    fx: f64,
    /// Focal length along y, in pixels.
    #[pyo3(get)]
    fy: f64,
    /// Principal point column.
    #[pyo3(get)]
    cx: f64,
    /// Principal point row.
    #[pyo3(get)]
    cy: f64,
    /// Multiplier from a depth value to Z (1.0 for depth in metres).
    #[pyo3(get)]
    depth_scale: f64,
}

#[pymethods]
impl PyPinhole {
    #[new]
    #[pyo3(signature = (fx, fy, cx, cy, depth_scale = 1.0))]
    fn new(fx: f64, fy: f64, cx: f64, cy: f64, depth_scale: f64) -> PyResult<Self> {
        if ![fx, fy, cx, cy, depth_scale].iter().all(|v| v.is_finite()) {
            return Err(PyValueError::new_err("Pinhole: parameters must be finite"));
        }
        if fx <= 0.0 || fy <= 0.0 || depth_scale <= 0.0 {
            return Err(PyValueError::new_err("Pinhole: fx, fy and depth_scale must be positive"));
        }
        Ok(Self { fx, fy, cx, cy, depth_scale })
    }

    fn __repr__(&self) -> String {
        let Self { fx, fy, cx, cy, depth_scale } = self;
        format!("Pinhole(fx={fx:?}, fy={fy:?}, cx={cx:?}, cy={cy:?}, depth_scale={depth_scale:?})")
    }
}

/// The ABW structured-light scanner with calibration 0 or 1; depth values are the raw 8-bit range values.
#[pyclass(frozen, eq, module = "rangeseg", name = "ABW")]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PyAbw {
    /// The calibration: 0 or 1.
    #[pyo3(get)]
    calibration: u8,
}

#[pymethods]
impl PyAbw {
    #[new]
    fn new(calibration: i64) -> PyResult<Self> {
        match calibration {
            0 | 1 => Ok(Self { calibration: calibration as u8 }),
            c => Err(PyValueError::new_err(format!("ABW: calibration must be 0 or 1, got {c}"))),
        }
    }

    fn __repr__(&self) -> String {
        format!("ABW({})", self.calibration)
    }
}

/// No calibration: the 3D point of pixel (x, y) with value v is (x, y, v) itself.
#[pyclass(frozen, eq, module = "rangeseg", name = "Grid")]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PyGrid;

#[pymethods]
impl PyGrid {
    #[new]
    fn new() -> Self {
        Self
    }

    fn __repr__(&self) -> &'static str {
        "Grid()"
    }
}

/// The Rust camera of a Python camera object.
fn camera_from(obj: &Bound<'_, PyAny>) -> PyResult<Camera> {
    if let Ok(p) = obj.cast::<PyPinhole>() {
        let PyPinhole { fx, fy, cx, cy, depth_scale } = *p.get();
        return Ok(Camera::Pinhole { fx, fy, cx, cy, depth_scale });
    }
    if let Ok(a) = obj.cast::<PyAbw>() {
        return Ok(if a.get().calibration == 0 { Camera::ABW0 } else { Camera::ABW1 });
    }
    if obj.cast::<PyGrid>().is_ok() {
        return Ok(Camera::Grid);
    }
    Err(PyTypeError::new_err(format!(
        "camera must be rangeseg.Pinhole, rangeseg.ABW or rangeseg.Grid, got {}",
        obj.get_type().name()?
    )))
}

/// The Python camera object of a Rust camera.
fn camera_to(py: Python<'_>, camera: &Camera) -> PyResult<Py<PyAny>> {
    Ok(match *camera {
        Camera::Pinhole { fx, fy, cx, cy, depth_scale } => {
            Py::new(py, PyPinhole { fx, fy, cx, cy, depth_scale })?.into_any()
        }
        Camera::Abw(cal) if cal == AbwCalibration::CAL0 => Py::new(py, PyAbw { calibration: 0 })?.into_any(),
        Camera::Abw(cal) if cal == AbwCalibration::CAL1 => Py::new(py, PyAbw { calibration: 1 })?.into_any(),
        Camera::Abw(cal) => {
            return Err(PyValueError::new_err(format!("ABW calibration {cal:?} has no Python camera")));
        }
        Camera::Grid => Py::new(py, PyGrid)?.into_any(),
    })
}

/// Parses a CLI camera spec: `abw0`, `abw1`, `grid` or `pinhole:fx,fy,cx,cy[,depth_scale]`.
#[pyfunction]
fn parse_camera(py: Python<'_>, spec: &str) -> PyResult<Py<PyAny>> {
    let camera = rangeio::parse_camera(spec).map_err(PyValueError::new_err)?;
    camera_to(py, &camera)
}

/// A validated pipeline configuration (`configs/*.toml`).
#[pyclass(frozen, module = "rangeseg", name = "Config")]
#[derive(Debug, Clone)]
pub struct PyConfig {
    inner: Config,
}

#[pymethods]
impl PyConfig {
    /// The built-in defaults (as `configs/default.toml`).
    #[new]
    fn new() -> Self {
        Self { inner: Config::default() }
    }

    /// Reads and validates a TOML file.
    #[staticmethod]
    fn from_path(path: PathBuf) -> PyResult<Self> {
        Config::load(&path).map(|inner| Self { inner }).map_err(config_err)
    }

    /// Parses and validates a TOML text; `name` names it in errors.
    #[staticmethod]
    #[pyo3(signature = (text, name = "<config>"))]
    fn from_toml(text: &str, name: &str) -> PyResult<Self> {
        Config::from_toml(text, Path::new(name)).map(|inner| Self { inner }).map_err(config_err)
    }

    /// Builds from a JSON object of the same tables and keys as the TOML file; `name` names it in errors.
    #[staticmethod]
    #[pyo3(signature = (text, name = "<config dict>"))]
    fn from_json(text: &str, name: &str) -> PyResult<Self> {
        let table: toml::Table =
            serde_json::from_str(text).map_err(|e| ConfigError::new_err(format!("{name}: {e}")))?;
        Config::from_table(table, Path::new(name)).map(|inner| Self { inner }).map_err(config_err)
    }

    /// The configuration as TOML text.
    fn to_toml(&self) -> String {
        self.inner.to_toml()
    }

    /// The seed of every random choice.
    #[getter]
    fn seed(&self) -> u64 {
        self.inner.seed
    }

    fn __repr__(&self) -> String {
        format!("Config(seed={})", self.inner.seed)
    }
}

fn read_options(
    camera: Option<&Bound<'_, PyAny>>,
    depth_scale: Option<f64>,
    nyu_grey: bool,
) -> PyResult<rangeio::ReadOptions> {
    if let Some(s) = depth_scale
        && !(s.is_finite() && s > 0.0)
    {
        return Err(PyValueError::new_err(format!("depth_scale must be a positive number, got {s}")));
    }
    if nyu_grey && depth_scale.is_some() {
        return Err(PyValueError::new_err("nyu_grey and depth_scale cannot be used together"));
    }
    let camera = camera.map(camera_from).transpose()?;
    let opts = rangeio::ReadOptions { depth_scale, camera, ..Default::default() };
    if !nyu_grey {
        return Ok(opts);
    }
    // As the CLI's --nyu-grey: depth = 370 − grey and the Kinect intrinsics of the crop, unless a camera is given.
    let nyu = opts.nyu_grey();
    Ok(rangeio::ReadOptions { camera: camera.or(nyu.camera), ..nyu })
}

fn frame_to_py(py: Python<'_>, frame: rangeio::Frame) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
    let camera = camera_to(py, &frame.camera)?;
    let depth = grid_to_py(py, frame.range)?;
    Ok((depth, camera))
}

/// A grid as a 2-D numpy array (rows × columns), moving its buffer.
fn grid_to_py<T: numpy::Element>(py: Python<'_>, grid: Grid<T>) -> PyResult<Py<PyAny>> {
    let (w, h) = grid.dimensions();
    let a = Array2::from_shape_vec((h as usize, w as usize), grid.into_vec())
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(PyArray2::from_owned_array(py, a).into_any().unbind())
}

/// Reads a depth file of any format the CLI reads; returns `(depth, camera)` with depth as float32 (NaN = no
/// data) in the units the CLI uses (metres for metric sensors, raw values for ABW and 8-bit images);
/// `nyu_grey=True` reads the 8-bit NYU frames of Jin et al. as the CLI's `--nyu-grey` does.
#[pyfunction]
#[pyo3(signature = (path, camera = None, depth_scale = None, nyu_grey = false))]
fn read(
    py: Python<'_>,
    path: PathBuf,
    camera: Option<&Bound<'_, PyAny>>,
    depth_scale: Option<f64>,
    nyu_grey: bool,
) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
    let opts = read_options(camera, depth_scale, nyu_grey)?;
    let frame = py.detach(|| rangeio::read(&path, &opts)).map_err(read_err)?;
    frame_to_py(py, frame)
}

/// Like `read`, on the bytes of a file already in memory; `name` chooses the ABW calibration and names the
/// file in errors.
#[pyfunction]
#[pyo3(signature = (data, name, camera = None, depth_scale = None, nyu_grey = false))]
fn read_bytes(
    py: Python<'_>,
    data: &[u8],
    name: PathBuf,
    camera: Option<&Bound<'_, PyAny>>,
    depth_scale: Option<f64>,
    nyu_grey: bool,
) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
    let opts = read_options(camera, depth_scale, nyu_grey)?;
    let frame = rangeio::read_bytes(data, &name, &opts).map_err(read_err)?;
    frame_to_py(py, frame)
}

/// The range image of a 2-D float32 or uint16 numpy array: 0 and non-finite values become NaN (no data);
/// uint16 values are multiplied by `depth_scale` in f64 and rounded to f32, as the CLI reads 16-bit files.
fn range_from(depth: &Bound<'_, PyAny>, depth_scale: Option<f64>) -> PyResult<RangeImage> {
    let arr = depth.cast::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!("depth must be a numpy array, got {}", type_name(depth)))
    })?;
    if arr.ndim() != 2 {
        return Err(PyValueError::new_err(format!("depth must be a 2-D array, got shape {:?}", arr.shape())));
    }
    let (h, w) = (arr.shape()[0], arr.shape()[1]);
    if h == 0 || w == 0 {
        return Err(PyValueError::new_err(format!("depth is empty (shape ({h}, {w}))")));
    }
    let max = rangeio::MAX_SIDE as usize;
    if h > max || w > max {
        return Err(PyValueError::new_err(format!("depth is {w}×{h}: the largest side accepted is {max}")));
    }
    let dims = (w as u32, h as u32);
    if let Ok(a) = depth.extract::<PyReadonlyArray2<'_, f32>>() {
        if depth_scale.is_some() {
            return Err(PyValueError::new_err(
                "depth_scale applies to uint16 depth only (float32 is metres)",
            ));
        }
        let data =
            a.as_array().iter().map(|&v| if v == 0.0 || !v.is_finite() { f32::NAN } else { v }).collect();
        return Ok(Grid::from_vec(dims.0, dims.1, data).expect("w·h values"));
    }
    if let Ok(a) = depth.extract::<PyReadonlyArray2<'_, u16>>() {
        let s = match depth_scale {
            Some(s) if s.is_finite() && s > 0.0 => s,
            Some(s) => return Err(PyValueError::new_err(format!("depth_scale must be positive, got {s}"))),
            None => {
                return Err(PyValueError::new_err(
                    "uint16 depth needs depth_scale (metres per unit, e.g. 0.001 for millimetres)",
                ));
            }
        };
        let data =
            a.as_array().iter().map(|&v| if v == 0 { f32::NAN } else { (f64::from(v) * s) as f32 }).collect();
        return Ok(Grid::from_vec(dims.0, dims.1, data).expect("w·h values"));
    }
    Err(PyTypeError::new_err(format!(
        "depth must be float32 (metres) or uint16 (with depth_scale), got dtype {}",
        arr.dtype()
    )))
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
}

fn edges_to_py(py: Python<'_>, edges: &rangeimage::EdgeMap) -> PyResult<Py<PyAny>> {
    grid_to_py(py, edges.clone())
}

/// Runs the whole pipeline on a depth array with the GIL released; returns a dict of numpy arrays (`labels`,
/// `edges`, `c1`, `c2`), the plane columns (`planes`: a dict of arrays) and `timings` (ms per stage).
#[pyfunction]
#[pyo3(signature = (depth, camera, config = None, seed = None, depth_scale = None))]
fn segment<'py>(
    py: Python<'py>,
    depth: &Bound<'py, PyAny>,
    camera: &Bound<'py, PyAny>,
    config: Option<&Bound<'py, PyConfig>>,
    seed: Option<u64>,
    depth_scale: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let camera = camera_from(camera)?;
    let range = range_from(depth, depth_scale)?;
    let mut seg = rangeseg::pipeline::Segmenter::new(config_with_seed(config, seed));
    let planes = py.detach(|| {
        let out = seg.segment(&range, &camera);
        rangeseg::planes(&range, &out.fin.labels, &camera)
    });
    result_dict(py, &seg.into_output(), &planes)
}

/// The configuration of `config` (the defaults if `None`) with `seed` overriding its seed.
fn config_with_seed(config: Option<&Bound<'_, PyConfig>>, seed: Option<u64>) -> Config {
    let mut config = config.map_or_else(Config::default, |c| c.get().inner.clone());
    if let Some(seed) = seed {
        config.seed = seed;
    }
    config
}

/// The pipeline on a stream of depth arrays: keeps the working buffers of the previous frame, so frames of one
/// size allocate no image-sized memory after the first; each call returns what [`segment`] returns, bit for bit.
#[pyclass(module = "rangeseg", name = "Segmenter")]
struct PySegmenter {
    inner: rangeseg::pipeline::Segmenter,
}

#[pymethods]
impl PySegmenter {
    #[new]
    #[pyo3(signature = (config = None, seed = None))]
    fn new(config: Option<&Bound<'_, PyConfig>>, seed: Option<u64>) -> Self {
        Self { inner: rangeseg::pipeline::Segmenter::new(config_with_seed(config, seed)) }
    }

    /// Segments one frame (GIL released); the same dict as the module's `segment`.
    #[pyo3(signature = (depth, camera, depth_scale = None))]
    fn segment<'py>(
        &mut self,
        py: Python<'py>,
        depth: &Bound<'py, PyAny>,
        camera: &Bound<'py, PyAny>,
        depth_scale: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let camera = camera_from(camera)?;
        let range = range_from(depth, depth_scale)?;
        let seg = &mut self.inner;
        let planes = py.detach(|| {
            let out = seg.segment(&range, &camera);
            rangeseg::planes(&range, &out.fin.labels, &camera)
        });
        let out = self.inner.output();
        result_dict(py, out, &planes)
    }
}

/// The dict `segment` returns for one pipeline output and its planes.
fn result_dict<'py>(
    py: Python<'py>,
    out: &rangeseg::Output,
    planes: &[rangeseg::Plane],
) -> PyResult<Bound<'py, PyDict>> {
    let labels = out.fin.labels.map(|&l| i32::try_from(l).unwrap_or(-1));
    let d = PyDict::new(py);
    d.set_item("labels", grid_to_py(py, labels)?)?;
    d.set_item("edges", edges_to_py(py, out.fin.edges())?)?;
    d.set_item("c1", edges_to_py(py, &out.regions.c1)?)?;
    d.set_item("c2", edges_to_py(py, &out.canny.edges)?)?;

    let n = planes.len();
    let col = |f: &dyn Fn(&rangeseg::Plane) -> f64| Array1::from_iter(planes.iter().map(f));
    let mat3 = |f: &dyn Fn(&rangeseg::Plane) -> [f64; 3]| {
        Array2::from_shape_vec((n, 3), planes.iter().flat_map(f).collect()).expect("n×3")
    };
    let p = PyDict::new(py);
    let labels_col = Array1::from_iter(planes.iter().map(|p| i64::from(p.label)));
    p.set_item("label", PyArray1::from_owned_array(py, labels_col))?;
    p.set_item("normal", PyArray2::from_owned_array(py, mat3(&|p| p.normal)))?;
    p.set_item("d", PyArray1::from_owned_array(py, col(&|p| p.d)))?;
    p.set_item("centroid", PyArray2::from_owned_array(py, mat3(&|p| p.centroid)))?;
    let pixels = Array1::from_iter(planes.iter().map(|p| p.pixels as i64));
    p.set_item("pixels", PyArray1::from_owned_array(py, pixels))?;
    p.set_item("rms", PyArray1::from_owned_array(py, col(&|p| p.rms)))?;
    let bbox = Array2::from_shape_vec((n, 4), planes.iter().flat_map(|p| p.bbox.map(i64::from)).collect())
        .expect("n×4");
    p.set_item("bbox", PyArray2::from_owned_array(py, bbox))?;
    d.set_item("planes", p)?;

    let t = PyDict::new(py);
    let tm = out.timings;
    for (k, v) in
        [("features", tm.features), ("regiongrow", tm.regiongrow), ("vcanny", tm.vcanny), ("relax", tm.relax)]
    {
        t.set_item(k, v)?;
    }
    d.set_item("timings", t)?;
    Ok(d)
}

/// The native part of the `rangeseg` Python package.
#[pymodule]
fn _rangeseg(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<PyPinhole>()?;
    m.add_class::<PyAbw>()?;
    m.add_class::<PyGrid>()?;
    m.add_class::<PyConfig>()?;
    m.add_function(wrap_pyfunction!(parse_camera, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(read_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(segment, m)?)?;
    m.add_class::<PySegmenter>()?;
    m.add("RangesegError", py.get_type::<RangesegError>())?;
    m.add("ReadError", py.get_type::<ReadError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    Ok(())
}

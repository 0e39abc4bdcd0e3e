//! Mesh files (STL, binary or ASCII, and Wavefront OBJ) read for the scenario loader: a
//! `[[target.shapes]] kind = "mesh"` table names a `file`, which the loader reads here into the
//! shape's `vertices` and `triangles` before the core checks them (the core reads no files).

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Vertices (the file's units) and triangles (vertex indices) of a mesh file.
type Mesh = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// Reads an STL file (binary or ASCII) into indexed vertices and triangles.
fn read_stl(path: &Path) -> Result<Mesh, String> {
    let file = File::open(path).map_err(|e| e.to_string())?;
    let mesh = stl_io::read_stl(&mut BufReader::new(file))
        .map_err(|e| format!("not a valid STL file: {e}"))?;
    let vertices = mesh
        .vertices
        .iter()
        .map(|v| [v[0] as f64, v[1] as f64, v[2] as f64])
        .collect();
    let triangles = mesh
        .faces
        .iter()
        .map(|f| f.vertices.map(|i| i as u32))
        .collect();
    Ok((vertices, triangles))
}

/// Reads a Wavefront OBJ file (every object, polygons triangulated) into vertices and triangles.
fn read_obj(path: &Path) -> Result<Mesh, String> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) =
        tobj::load_obj(path, &options).map_err(|e| format!("not a valid OBJ file: {e}"))?;
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for model in models {
        let m = model.mesh;
        let base = vertices.len() as u32;
        vertices.extend(
            m.positions
                .chunks_exact(3)
                .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]),
        );
        triangles.extend(
            m.indices
                .chunks_exact(3)
                .map(|t| [base + t[0], base + t[1], base + t[2]]),
        );
    }
    Ok((vertices, triangles))
}

/// Reads a mesh file, STL or OBJ by its extension: `(vertices, triangles)`. Raises ValueError
/// with the reason (missing, unreadable, malformed, an unknown extension).
#[pyfunction]
pub fn read_mesh(path: &str) -> PyResult<Mesh> {
    let p = Path::new(path);
    let ext = p
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let result = match ext.as_str() {
        "stl" => read_stl(p),
        "obj" => read_obj(p),
        _ => Err(format!(
            "unknown mesh format '.{ext}': expected an .stl or .obj file"
        )),
    };
    result.map_err(PyValueError::new_err)
}

//! VTK files through the `vtkio` crate: legacy `.vtk` (structured points,
//! polydata, unstructured grids; ASCII or big-endian binary) and XML
//! (`.vti`, `.vtp`, `.vtu`; ASCII, base64 or raw appended data, zlib- or
//! lz4-compressed, either byte order), and the parallel `.pvti`, `.pvtp`,
//! `.pvtu` that name one piece file each.
//!
//! - [`volume::read_volume`]: image data (`.vti`, `.pvti`, legacy structured
//!   points) as a [`Volume`](crate::volume::Volume) of one point field.
//! - [`mesh::read_mesh`]: polydata and unstructured grids as a
//!   [`TriangleMesh`](crate::TriangleMesh), with one field as its scalars.
//! - [`FieldChoice`]: which array (`--field NAME`, `NAME:mag`, `NAME:0`).
//!
//! Known gaps of vtkio 0.7.0-rc2 (measured on files VTK 9.7 writes, see
//! `tests/vtk/`): raw (unencoded) appended data is an error (its support is
//! behind a feature the crate does not declare), and a compressed array of
//! no values (a polydata's empty `Verts`, which VTK writes by default) makes
//! it panic, which becomes an error here. 0.6.3 fails on both too, and on
//! legacy 5.1 unstructured grids.
//!
//! dpp parses the files itself (`Vtk::parse_xml`, `Vtk::parse_legacy_be`)
//! rather than through `Vtk::import`: that dispatches on the extension's
//! exact case, and its loading of parallel pieces does not say which piece
//! is missing. vtkio panics on some malformed input (an empty binary array,
//! offsets past the end); those panics are caught here and become errors
//! that name the file.

pub mod mesh;
pub mod volume;

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use thiserror::Error;
use vtkio::model::{Attribute, Attributes, DataSet, ElementType, IOBuffer, Piece};
use vtkio::Vtk;

/// A VTK file that cannot be used: the file and what is wrong with it.
#[derive(Clone, Debug, Error, PartialEq)]
#[error("{}: {what}", path.display())]
pub struct VtkError {
    pub path: PathBuf,
    pub what: String,
}

impl VtkError {
    pub fn new(path: &Path, what: impl Into<String>) -> VtkError {
        VtkError {
            path: path.to_path_buf(),
            what: what.into(),
        }
    }
}

/// The kinds of VTK file dpp reads, by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VtkKind {
    /// `.vtk`: a volume or a mesh, as its `DATASET` line says.
    Legacy,
    /// `.vti`, `.pvti`.
    Image { parallel: bool },
    /// `.vtp`, `.pvtp`, `.vtu`, `.pvtu`.
    Mesh { parallel: bool },
}

impl VtkKind {
    /// The kind of a file by its extension (any case), if it is a VTK file.
    pub fn of(path: &Path) -> Option<VtkKind> {
        let extension = path.extension()?.to_string_lossy().to_ascii_lowercase();
        Some(match extension.as_str() {
            "vtk" => VtkKind::Legacy,
            "vti" => VtkKind::Image { parallel: false },
            "pvti" => VtkKind::Image { parallel: true },
            "vtp" | "vtu" => VtkKind::Mesh { parallel: false },
            "pvtp" | "pvtu" => VtkKind::Mesh { parallel: true },
            _ => return None,
        })
    }
}

/// Whether `path` is a VTK file that holds a volume: `.vti`, `.pvti`, or a
/// legacy `.vtk` whose `DATASET` is `STRUCTURED_POINTS` (read from its
/// header; a file that cannot be read is not a volume, and the mesh reader
/// then says what is wrong with it).
pub fn is_volume_file(path: &Path) -> bool {
    match VtkKind::of(path) {
        Some(VtkKind::Image { .. }) => true,
        Some(VtkKind::Legacy) => legacy_dataset(path).is_some_and(|d| d == "STRUCTURED_POINTS"),
        _ => false,
    }
}

/// The `DATASET` keyword of a legacy file's header (its first lines).
fn legacy_dataset(path: &Path) -> Option<String> {
    let mut head = Vec::new();
    File::open(path)
        .ok()?
        .take(1024)
        .read_to_end(&mut head)
        .ok()?;
    let text = String::from_utf8_lossy(&head);
    text.lines().take(6).find_map(|line| {
        let mut words = line.split_whitespace();
        (words.next()?.eq_ignore_ascii_case("DATASET"))
            .then(|| words.next().map(|w| w.to_ascii_uppercase()))?
    })
}

/// Reads one VTK file (a parallel file's pieces are left unread), turning a
/// vtkio panic into an error.
pub(crate) fn parse(path: &Path) -> Result<DataSet, VtkError> {
    let kind = VtkKind::of(path).ok_or_else(|| {
        VtkError::new(
            path,
            "not a VTK file (expected .vtk, .vti, .vtp, .vtu, .pvti, .pvtp or .pvtu)",
        )
    })?;
    let file = File::open(path).map_err(|e| VtkError::new(path, e.to_string()))?;
    let reader = BufReader::new(file);
    let parsed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match kind {
        // Legacy binary data is big-endian by the format's definition.
        VtkKind::Legacy => Vtk::parse_legacy_be(reader),
        _ => Vtk::parse_xml(reader),
    }));
    match parsed {
        Ok(Ok(vtk)) => Ok(vtk.data),
        Ok(Err(error)) if error.to_string().contains("unknown variant `raw`") => Err(VtkError::new(
            path,
            "raw (unencoded) appended data is not supported (vtkio 0.7.0-rc2 reads base64 only): save the file with appended data encoded, or inline binary or ASCII",
        )),
        Ok(Err(error)) => Err(VtkError::new(path, format!("malformed VTK file: {error}"))),
        Err(_) => Err(VtkError::new(
            path,
            "malformed VTK file (the vtkio reader failed on it)",
        )),
    }
}

/// The files a parallel file's pieces name, in its order, relative to its
/// folder; each must exist (the error names the first that does not).
pub fn piece_files(path: &Path) -> Result<Vec<PathBuf>, VtkError> {
    let sources: Vec<String> = match parse(path)? {
        DataSet::ImageData { pieces, .. } => sources(pieces),
        DataSet::PolyData { pieces, .. } => sources(pieces),
        DataSet::UnstructuredGrid { pieces, .. } => sources(pieces),
        _ => {
            return Err(VtkError::new(
                path,
                "not image data, polydata or an unstructured grid",
            ))
        }
    };
    if sources.is_empty() {
        return Err(VtkError::new(
            path,
            "the parallel file names no piece files",
        ));
    }
    let folder = path.parent().unwrap_or(Path::new(""));
    sources
        .into_iter()
        .map(|source| {
            let piece = folder.join(source);
            if piece.is_file() {
                Ok(piece)
            } else {
                Err(VtkError::new(
                    path,
                    format!("its piece {} is missing", piece.display()),
                ))
            }
        })
        .collect()
}

fn sources<P>(pieces: Vec<Piece<P>>) -> Vec<String> {
    (pieces.into_iter())
        .filter_map(|piece| match piece {
            Piece::Source(source, _) => Some(source),
            _ => None,
        })
        .collect()
}

/// The inline pieces of a serial file (a parallel one's piece files are
/// read by the callers, so that errors name them).
pub(crate) fn inline_pieces<P>(path: &Path, pieces: Vec<Piece<P>>) -> Result<Vec<P>, VtkError> {
    (pieces.into_iter())
        .map(|piece| match piece {
            Piece::Inline(piece) => Ok(*piece),
            _ => Err(VtkError::new(
                path,
                "a serial VTK file whose piece is stored elsewhere",
            )),
        })
        .collect()
}

/// Which array is the scalar field: `--field NAME`, `NAME:mag` (a vector's
/// length), `NAME:N` (component N). Without a name: the active scalars
/// (point data first), else the first array (point data first). A vector
/// without a component is taken by its magnitude.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FieldChoice {
    pub name: Option<String>,
    pub component: Component,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Component {
    /// The value of a one-component array, the magnitude of a longer one.
    #[default]
    Whole,
    Magnitude,
    Index(usize),
}

impl FromStr for FieldChoice {
    type Err = String;

    fn from_str(text: &str) -> Result<FieldChoice, String> {
        let (name, component) = match text.rsplit_once(':') {
            Some((name, "mag")) => (name, Component::Magnitude),
            Some((name, index)) if index.bytes().all(|b| b.is_ascii_digit()) => {
                let index = index
                    .parse()
                    .map_err(|_| format!("--field {text}: the component {index} is too large"))?;
                (name, Component::Index(index))
            }
            _ => (text, Component::Whole),
        };
        if name.is_empty() {
            return Err(format!(
                "--field {text}: give an array's name (NAME, NAME:mag or NAME:0)"
            ));
        }
        Ok(FieldChoice {
            name: Some(name.to_string()),
            component,
        })
    }
}

/// vtkio leaves out an XML array whose length does not match its points or
/// cells without a word, so a missing array may be a broken one.
pub(crate) const XML_DROPS: &str =
    " (an XML array whose length does not match the points or cells is left out)";

/// Where a field's values live.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Association {
    Point,
    Cell,
}

impl Association {
    fn noun(self) -> &'static str {
        match self {
            Association::Point => "points",
            Association::Cell => "cells",
        }
    }
}

/// One scalar per point or per cell, as f32.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    pub association: Association,
    pub values: Vec<f32>,
}

/// One array of a piece, legacy FIELD arrays included.
struct Array<'a> {
    name: &'a str,
    components: usize,
    data: &'a IOBuffer,
    active: bool,
    association: Association,
}

fn arrays(attributes: &Attributes) -> Vec<Array<'_>> {
    let mut all = Vec::new();
    for (association, list) in [
        (Association::Point, &attributes.point),
        (Association::Cell, &attributes.cell),
    ] {
        for attribute in list {
            match attribute {
                Attribute::DataArray(array) => {
                    // A lookup table is colours for legacy scalars, not a field.
                    if matches!(array.elem, ElementType::LookupTable) {
                        continue;
                    }
                    all.push(Array {
                        name: &array.name,
                        components: array.elem.num_comp() as usize,
                        data: &array.data,
                        active: matches!(array.elem, ElementType::Scalars { .. }),
                        association,
                    })
                }
                Attribute::Field { data_array, .. } => {
                    all.extend(data_array.iter().map(|array| Array {
                        name: &array.name,
                        components: array.elem as usize,
                        data: &array.data,
                        active: false,
                        association,
                    }))
                }
            }
        }
    }
    all
}

impl FieldChoice {
    /// The field this choice picks from a piece's attributes with `points`
    /// points and `cells` cells, with the choice made concrete (its array's
    /// name) so that the other pieces of a parallel file take the same
    /// array. `Ok(None)`: no name was given and the piece has no arrays.
    pub(crate) fn pick(
        &self,
        path: &Path,
        attributes: &Attributes,
        points: usize,
        cells: usize,
    ) -> Result<Option<(Field, FieldChoice)>, VtkError> {
        let all = arrays(attributes);
        let chosen = match &self.name {
            Some(name) => all.iter().find(|a| a.name == name).ok_or_else(|| {
                let names: Vec<String> = all
                    .iter()
                    .map(|a| format!("{} ({})", a.name, a.association.noun()))
                    .collect();
                VtkError::new(
                    path,
                    format!(
                        "no array named `{name}`; its arrays: {}{XML_DROPS}",
                        if names.is_empty() {
                            "none".to_string()
                        } else {
                            names.join(", ")
                        }
                    ),
                )
            })?,
            None => match all.iter().find(|a| a.active).or(all.first()) {
                Some(array) => array,
                None => return Ok(None),
            },
        };
        let expected = match chosen.association {
            Association::Point => points,
            Association::Cell => cells,
        };
        let field = field_values(path, chosen, self.component, expected)?;
        let concrete = FieldChoice {
            name: Some(chosen.name.to_string()),
            component: self.component,
        };
        Ok(Some((field, concrete)))
    }
}

fn field_values(
    path: &Path,
    array: &Array,
    component: Component,
    expected: usize,
) -> Result<Field, VtkError> {
    let name = array.name;
    let components = array.components.max(1);
    let values: Vec<f64> = array.data.cast_into().ok_or_else(|| {
        VtkError::new(
            path,
            format!("array `{name}`: bit arrays are not supported"),
        )
    })?;
    if values.len() != expected.saturating_mul(components) {
        return Err(VtkError::new(
            path,
            format!(
                "array `{name}` has {} values ({components} per tuple), but the piece has {expected} {}",
                values.len(),
                array.association.noun()
            ),
        ));
    }
    let tuples = values.chunks_exact(components);
    let values: Vec<f32> = match component {
        Component::Index(index) if index >= components => {
            return Err(VtkError::new(
                path,
                format!(
                    "array `{name}` has {components} components; component {index} does not exist"
                ),
            ))
        }
        Component::Index(index) => tuples.map(|t| t[index] as f32).collect(),
        Component::Whole if components == 1 => tuples.map(|t| t[0] as f32).collect(),
        Component::Whole | Component::Magnitude => tuples
            .map(|t| t.iter().map(|v| v * v).sum::<f64>().sqrt() as f32)
            .collect(),
    };
    Ok(Field {
        association: array.association,
        values,
    })
}

/// The committed fixtures (`tests/vtk/`, written by
/// `scripts/make-vtk-fixtures.py` with VTK's own writers), for tests.
#[cfg(test)]
pub(crate) fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/vtk")
        .join(name)
}

/// Reads copies of the fixtures `names`, each with up to 8 bytes replaced at
/// random and its end cut by up to 15 bytes, `rounds` times per fixture:
/// the readers' fuzz test, which only asks that `read` returns.
#[cfg(test)]
pub(crate) fn read_mutated_fixtures(
    names: &[&str],
    seed: u64,
    rounds: usize,
    read: impl Fn(&std::path::Path),
) {
    let mut random = dpp_runtime::random::SplitMix64::new(seed);
    let dir = tempfile::tempdir().unwrap();
    for name in names {
        let good = std::fs::read(fixture(name)).unwrap();
        for round in 0..rounds {
            let mut bytes = good.clone();
            for _ in 0..1 + round % 8 {
                let at = (random.next_u64() % bytes.len() as u64) as usize;
                bytes[at] = random.next_u64() as u8;
            }
            let len = bytes.len() - (random.next_u64() % 16) as usize;
            let path = dir.path().join(name);
            std::fs::write(&path, &bytes[..len]).unwrap();
            read(&path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_choices_parse() {
        let choice = |text: &str| text.parse::<FieldChoice>();
        assert_eq!(
            choice("rho").unwrap(),
            FieldChoice {
                name: Some("rho".into()),
                component: Component::Whole
            }
        );
        assert_eq!(choice("v:mag").unwrap().component, Component::Magnitude);
        assert_eq!(choice("v:2").unwrap().component, Component::Index(2));
        // A name with a colon keeps it when what follows is no component.
        assert_eq!(choice("a:b").unwrap().name.as_deref(), Some("a:b"));
        assert!(choice(":0").is_err());
        assert!(choice("v:99999999999999999999999").is_err());
    }

    #[test]
    fn kinds_by_extension() {
        assert_eq!(
            VtkKind::of(Path::new("a/B.PVTU")),
            Some(VtkKind::Mesh { parallel: true })
        );
        assert_eq!(VtkKind::of(Path::new("a.vtk")), Some(VtkKind::Legacy));
        assert_eq!(VtkKind::of(Path::new("a.obj")), None);
    }
}

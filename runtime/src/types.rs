//! Element types of arrays and types of host scalars.

use serde::Serialize;
use std::fmt;

/// Index of a record type in the functor library's [`RecordRegistry`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct RecordId(pub u32);

/// The type of one element of an array.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub enum ElemType {
    Bool,
    U32,
    I32,
    F32,
    Vec2,
    Vec3,
    Vec4,
    Record(RecordId),
}

impl ElemType {
    pub const PRIMITIVES: [ElemType; 7] = [
        ElemType::Bool,
        ElemType::U32,
        ElemType::I32,
        ElemType::F32,
        ElemType::Vec2,
        ElemType::Vec3,
        ElemType::Vec4,
    ];

    /// The spelling used in the language and in signatures (`vec3`, `u32`, `Ray`).
    pub fn name(self, records: &RecordRegistry) -> String {
        match self {
            ElemType::Bool => "bool".into(),
            ElemType::U32 => "u32".into(),
            ElemType::I32 => "i32".into(),
            ElemType::F32 => "f32".into(),
            ElemType::Vec2 => "vec2".into(),
            ElemType::Vec3 => "vec3".into(),
            ElemType::Vec4 => "vec4".into(),
            ElemType::Record(id) => records.get(id).name.clone(),
        }
    }

    pub fn is_numeric(self) -> bool {
        !matches!(self, ElemType::Bool | ElemType::Record(_))
    }

    pub fn is_integer(self) -> bool {
        matches!(self, ElemType::U32 | ElemType::I32)
    }

    pub fn is_vector(self) -> bool {
        matches!(self, ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4)
    }

    /// How many numbers an element holds: 1 for a scalar, 2–4 for a vector
    /// (0 for a bool or a record, which are not numbers).
    pub fn components(self) -> u32 {
        match self {
            ElemType::U32 | ElemType::I32 | ElemType::F32 => 1,
            ElemType::Vec2 => 2,
            ElemType::Vec3 => 3,
            ElemType::Vec4 => 4,
            ElemType::Bool | ElemType::Record(_) => 0,
        }
    }

    /// The bytes one element takes in a column (a `bool` is one byte; a
    /// record, its fields' together): what MPI messages carry per element and
    /// the stride of the CPU's compiled loops.
    pub fn bytes(self, records: &RecordRegistry) -> usize {
        match self {
            ElemType::Bool => 1,
            ElemType::U32 | ElemType::I32 | ElemType::F32 => 4,
            ElemType::Vec2 => 8,
            ElemType::Vec3 => 12,
            ElemType::Vec4 => 16,
            ElemType::Record(id) => records
                .get(id)
                .fields
                .iter()
                .map(|(_, field)| field.bytes(records))
                .sum(),
        }
    }
}

/// A record type registered by the functor library (`Ray`, `Hit`, …): named
/// fields of non-record element types. Backends store records as they see fit
/// (the CPU backend keeps one column per field, so `a.field` is zero-copy).
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct RecordType {
    pub name: String,
    pub fields: Vec<(String, ElemType)>,
    pub doc: String,
}

impl RecordType {
    pub fn field_index(&self, name: &str) -> Option<usize> {
        self.fields.iter().position(|(n, _)| n == name)
    }
}

#[derive(Clone, Debug, Default)]
pub struct RecordRegistry {
    records: Vec<RecordType>,
}

impl RecordRegistry {
    /// Registers a record type; field types must not be records.
    pub fn register(&mut self, record: RecordType) -> RecordId {
        assert!(
            record
                .fields
                .iter()
                .all(|(_, t)| !matches!(t, ElemType::Record(_))),
            "record fields must be primitive element types"
        );
        assert!(
            !record.fields.is_empty(),
            "a record needs at least one field"
        );
        self.records.push(record);
        RecordId(self.records.len() as u32 - 1)
    }

    pub fn get(&self, id: RecordId) -> &RecordType {
        &self.records[id.0 as usize]
    }

    pub fn find(&self, name: &str) -> Option<RecordId> {
        self.records
            .iter()
            .position(|r| r.name == name)
            .map(|i| RecordId(i as u32))
    }

    pub fn iter(&self) -> impl Iterator<Item = (RecordId, &RecordType)> {
        self.records
            .iter()
            .enumerate()
            .map(|(i, r)| (RecordId(i as u32), r))
    }
}

/// The type of a host scalar: a `param`, a uniform field, `len(a)`, a `reduce` result.
/// Integer host scalars are 64-bit on the host; they become `u32` or `i32` where
/// an element type is needed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
pub enum HostType {
    Bool,
    Int,
    Float,
    Vec2,
    Vec3,
    Vec4,
}

impl fmt::Display for HostType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            HostType::Bool => "bool",
            HostType::Int => "int",
            HostType::Float => "float",
            HostType::Vec2 => "vec2",
            HostType::Vec3 => "vec3",
            HostType::Vec4 => "vec4",
        })
    }
}

impl HostType {
    /// Whether a value of type `self` may be passed where `expected` is declared
    /// (integers widen to floats; nothing else converts implicitly).
    pub fn fits(self, expected: HostType) -> bool {
        self == expected || (self == HostType::Int && expected == HostType::Float)
    }

    /// The element type a host scalar of this type has when it fills an array.
    pub fn elem_type(self) -> ElemType {
        match self {
            HostType::Bool => ElemType::Bool,
            HostType::Int => ElemType::U32,
            HostType::Float => ElemType::F32,
            HostType::Vec2 => ElemType::Vec2,
            HostType::Vec3 => ElemType::Vec3,
            HostType::Vec4 => ElemType::Vec4,
        }
    }
}

/// The associative operations the backends implement natively for `reduce`, `scan`
/// and combining `scatter` (their identities are well known per element type).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
pub enum MonoidOp {
    Add,
    Mul,
    Min,
    Max,
    Or,
    And,
}

impl MonoidOp {
    /// The functor that performs the operation, as pipelines spell it.
    pub fn name(self) -> &'static str {
        match self {
            MonoidOp::Add => "add",
            MonoidOp::Mul => "mul",
            MonoidOp::Min => "min",
            MonoidOp::Max => "max",
            MonoidOp::Or => "or",
            MonoidOp::And => "and",
        }
    }
}

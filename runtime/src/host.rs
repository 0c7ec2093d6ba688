//! Host scalar values: params, uniforms and the scalars that control flow reads.

use crate::types::HostType;
use glam::{Vec2, Vec3, Vec4};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt;

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum HostValue {
    Bool(bool),
    Int(i64),
    Float(f64),
    Vec2([f32; 2]),
    Vec3([f32; 3]),
    Vec4([f32; 4]),
}

impl HostValue {
    pub fn host_type(&self) -> HostType {
        match self {
            HostValue::Bool(_) => HostType::Bool,
            HostValue::Int(_) => HostType::Int,
            HostValue::Float(_) => HostType::Float,
            HostValue::Vec2(_) => HostType::Vec2,
            HostValue::Vec3(_) => HostType::Vec3,
            HostValue::Vec4(_) => HostType::Vec4,
        }
    }

    pub fn as_bool(&self) -> Option<bool> {
        match *self {
            HostValue::Bool(b) => Some(b),
            _ => None,
        }
    }

    pub fn as_int(&self) -> Option<i64> {
        match *self {
            HostValue::Int(i) => Some(i),
            _ => None,
        }
    }

    /// Integers widen to floats.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            HostValue::Int(i) => Some(i as f64),
            HostValue::Float(f) => Some(f),
            _ => None,
        }
    }

    pub fn as_f32(&self) -> Option<f32> {
        self.as_f64().map(|f| f as f32)
    }

    /// A non-negative integer that fits in `u32`.
    pub fn as_u32(&self) -> Option<u32> {
        self.as_int().and_then(|i| u32::try_from(i).ok())
    }

    pub fn as_vec2(&self) -> Option<Vec2> {
        match *self {
            HostValue::Vec2(v) => Some(Vec2::from(v)),
            _ => None,
        }
    }

    pub fn as_vec3(&self) -> Option<Vec3> {
        match *self {
            HostValue::Vec3(v) => Some(Vec3::from(v)),
            _ => None,
        }
    }

    pub fn as_vec4(&self) -> Option<Vec4> {
        match *self {
            HostValue::Vec4(v) => Some(Vec4::from(v)),
            _ => None,
        }
    }
}

impl fmt::Display for HostValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HostValue::Bool(b) => write!(f, "{b}"),
            HostValue::Int(i) => write!(f, "{i}"),
            HostValue::Float(x) => write!(f, "{x:?}"),
            HostValue::Vec2([x, y]) => write!(f, "vec2({x:?}, {y:?})"),
            HostValue::Vec3([x, y, z]) => write!(f, "vec3({x:?}, {y:?}, {z:?})"),
            HostValue::Vec4([x, y, z, w]) => write!(f, "vec4({x:?}, {y:?}, {z:?}, {w:?})"),
        }
    }
}

/// Named uniform records (`camera`, `scene`) and their fields, as the host sees them.
/// The functor library declares their types ([`UniformSchema`]); the scene and camera
/// fill the values before a run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Uniforms {
    pub records: BTreeMap<String, BTreeMap<String, HostValue>>,
}

impl Uniforms {
    pub fn get(&self, record: &str, field: &str) -> Option<HostValue> {
        self.records.get(record)?.get(field).copied()
    }

    pub fn set(&mut self, record: &str, field: &str, value: HostValue) {
        self.records
            .entry(record.to_string())
            .or_default()
            .insert(field.to_string(), value);
    }
}

/// The declared types of the uniforms, known without a scene (for `dpp plan`, `dpp check`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UniformSchema {
    pub records: BTreeMap<String, BTreeMap<String, HostType>>,
}

impl UniformSchema {
    pub fn declare(&mut self, record: &str, field: &str, ty: HostType) {
        self.records
            .entry(record.to_string())
            .or_default()
            .insert(field.to_string(), ty);
    }
}

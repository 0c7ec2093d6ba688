//! The body of a PLY file, decoded in parallel: each element's records are
//! first located (ASCII: one record a line; binary: fixed-size records by
//! arithmetic, records with lists by one pass over their counts), then cut
//! into chunks of [`RECORDS_PER_CHUNK`] that are decoded on rayon and joined
//! in file order. The result does not depend on the chunk size or the thread
//! count; `ply::tests` checks it against `ply-rs-bw`'s own element reader.
//!
//! It accepts what that reader accepts: ASCII numbers as its grammar writes
//! them (`[-+]?[0-9]+(.[0-9]+)?([eE][-+]?[0-9]+)?`, separated by spaces or
//! tabs; a line may hold more values than the element has properties), each
//! parsed as its declared type (an `int` property does not take `1.5`), then
//! converted to `f32` exactly as before; an ASCII list's count is any
//! non-negative integer, a binary one's must fit its type and not be negative.

use crate::ply::ReadError;
use glam::Vec3;
use ply_rs_bw::ply::{ElementDef, Encoding, PropertyType, ScalarType};
use rayon::prelude::*;
use std::ops::Range;

/// Records one task decodes: enough to outweigh a task's scheduling, few
/// enough for two threads to share a 100K-triangle mesh evenly.
pub const RECORDS_PER_CHUNK: usize = 16384;

/// How the body's bytes encode numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodyEncoding {
    Ascii,
    Binary { big_endian: bool },
}

impl BodyEncoding {
    pub fn of(encoding: Encoding) -> BodyEncoding {
        match encoding {
            Encoding::Ascii => BodyEncoding::Ascii,
            Encoding::BinaryBigEndian => BodyEncoding::Binary { big_endian: true },
            Encoding::BinaryLittleEndian => BodyEncoding::Binary { big_endian: false },
        }
    }
}

/// Where a vertex property's value goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexSlot {
    Position(usize),
    Normal(usize),
    Scalar,
    Skipped,
}

/// The vertex element's values, in file order.
#[derive(Debug, Default)]
pub struct Vertices {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub scalars: Vec<f32>,
}

/// The face element as triangles (each face fanned, faces in file order), or
/// the first face (in file order) that cannot be one.
pub type Triangles = Result<Vec<[u32; 3]>, ReadError>;

/// One element's records in the body: the bytes of each chunk of up to
/// `records_per_chunk` records, and the number of each chunk's first record.
struct Located {
    chunks: Vec<Range<usize>>,
    first_records: Vec<usize>,
    /// The file's line of the element's first record (ASCII, for messages).
    first_line: usize,
}

/// The body's bytes after the header, its encoding, and how far it is read.
pub struct Body<'a> {
    bytes: &'a [u8],
    encoding: BodyEncoding,
    position: usize,
    /// The file's line number at `position` (ASCII, for messages).
    line: usize,
    records_per_chunk: usize,
}

impl<'a> Body<'a> {
    /// `first_line`: the file's line number of the body's first line (for
    /// messages); `records_per_chunk`: [`RECORDS_PER_CHUNK`] but in tests,
    /// which check that the result does not depend on it.
    pub fn new(
        bytes: &'a [u8],
        encoding: BodyEncoding,
        first_line: usize,
        records_per_chunk: usize,
    ) -> Body<'a> {
        Body {
            bytes,
            encoding,
            position: 0,
            line: first_line,
            records_per_chunk: records_per_chunk.max(1),
        }
    }

    /// Reads (and checks) an element that is not needed.
    pub fn skip(&mut self, element: &ElementDef) -> Result<(), ReadError> {
        let slots = vec![VertexSlot::Skipped; element.properties.len()];
        self.vertices(element, &slots).map(drop)
    }

    /// Reads the vertex element, each property into its slot (one per
    /// property, in the header's order).
    pub fn vertices(
        &mut self,
        element: &ElementDef,
        slots: &[VertexSlot],
    ) -> Result<Vertices, ReadError> {
        let located = self.locate(element)?;
        let normals = slots.iter().any(|s| matches!(s, VertexSlot::Normal(_)));
        let scalar = slots.contains(&VertexSlot::Scalar);
        let parts: Vec<Result<Vertices, ReadError>> = self
            .chunks(element, &located)
            .map(|mut records| {
                let mut part = Vertices::default();
                while records.next_record()? {
                    // Position, normal, scalar; a property the record lacks reads 0.
                    let mut values = [0.0f32; 7];
                    for ((name, property), &slot) in element.properties.iter().zip(slots) {
                        let PropertyType::Scalar(kind) = &property.data_type else {
                            records.list(name, &property.data_type, |_| Ok(()))?;
                            continue;
                        };
                        let value = records.scalar(name, kind)? as f32;
                        match slot {
                            VertexSlot::Position(axis) => values[axis] = value,
                            VertexSlot::Normal(axis) => values[3 + axis] = value,
                            VertexSlot::Scalar => values[6] = value,
                            VertexSlot::Skipped => {}
                        }
                    }
                    part.positions
                        .push(Vec3::new(values[0], values[1], values[2]));
                    if normals {
                        part.normals
                            .push(Vec3::new(values[3], values[4], values[5]));
                    }
                    if scalar {
                        part.scalars.push(values[6]);
                    }
                }
                Ok(part)
            })
            .collect();
        let mut whole = Vertices::default();
        for part in parts {
            let part = part?;
            whole.positions.extend(part.positions);
            whole.normals.extend(part.normals);
            whole.scalars.extend(part.scalars);
        }
        Ok(whole)
    }

    /// Reads the face element: its list property `indices` fanned into
    /// triangles. A malformed record is the outer error; a face of fewer
    /// than three or of negative indices the inner one, as the first such
    /// face in file order, after the whole element has been read.
    pub fn faces(&mut self, element: &ElementDef, indices: &str) -> Result<Triangles, ReadError> {
        let located = self.locate(element)?;
        let parts: Vec<Result<Triangles, ReadError>> = self
            .chunks(element, &located)
            .map(|mut records| {
                let mut triangles = Vec::new();
                let mut bad_face = None;
                let mut corners: Vec<i64> = Vec::new();
                while records.next_record()? {
                    let face = records.record;
                    corners.clear();
                    for (name, property) in &element.properties {
                        match &property.data_type {
                            PropertyType::Scalar(kind) => {
                                records.scalar(name, kind)?;
                            }
                            PropertyType::List(_, item) if name == indices => {
                                if matches!(item, ScalarType::Float | ScalarType::Double) {
                                    return Err(ReadError::Unsupported(format!(
                                        "the face element's `{name}` list holds {item:?} values; vertex indices must be integers"
                                    )));
                                }
                                records.list(name, &property.data_type, |value| {
                                    corners.push(value as i64);
                                    Ok(())
                                })?;
                            }
                            PropertyType::List(..) => {
                                records.list(name, &property.data_type, |_| Ok(()))?;
                            }
                        }
                    }
                    if bad_face.is_some() {
                        continue;
                    }
                    if corners.iter().any(|&v| v < 0) {
                        bad_face = Some(ReadError::NegativeIndex { face });
                    } else if corners.len() < 3 {
                        bad_face = Some(ReadError::ShortFace {
                            face,
                            count: corners.len(),
                        });
                    } else {
                        for pair in corners[1..].windows(2) {
                            triangles.push([corners[0], pair[0], pair[1]].map(|v| v as u32));
                        }
                    }
                }
                Ok(bad_face.map_or(Ok(triangles), Err))
            })
            .collect();
        // Every chunk's malformed record first (a serial read stops there),
        // then the first face that is no triangles.
        let parts = parts.into_iter().collect::<Result<Vec<_>, _>>()?;
        let mut whole = Vec::new();
        for part in parts {
            match part {
                Ok(triangles) => whole.extend(triangles),
                Err(face) => return Ok(Err(face)),
            }
        }
        Ok(Ok(whole))
    }

    /// The chunks of `element`'s records from the current position, in
    /// parallel; moves past them.
    fn chunks<'b>(
        &'b self,
        element: &'b ElementDef,
        located: &'b Located,
    ) -> impl IndexedParallelIterator<Item = Records<'b>> + 'b {
        (located.chunks.par_iter())
            .zip(&located.first_records)
            .map(move |(range, &first)| Records {
                bytes: &self.bytes[range.clone()],
                position: 0,
                encoding: self.encoding,
                element,
                record: first,
                next: first,
                first_line: located.first_line,
                tokens: Vec::new(),
                next_token: 0,
            })
    }

    /// Finds `element`'s records from the current position, in chunks, and
    /// moves past them.
    fn locate(&mut self, element: &ElementDef) -> Result<Located, ReadError> {
        let per_chunk = self.records_per_chunk;
        let mut located = Located {
            chunks: Vec::new(),
            first_records: Vec::new(),
            first_line: self.line,
        };
        let missing = |got: usize| {
            ReadError::Parse(format!(
                "unexpected end of file while reading element `{}` (expected {} records, got {got})",
                element.name, element.count
            ))
        };
        // Records of unknown size, one at a time: `end_of` finds where the
        // record starting at a position ends.
        let walk = |located: &mut Located,
                    end_of: &mut dyn FnMut(usize, usize) -> Result<usize, ReadError>|
         -> Result<usize, ReadError> {
            let (mut position, mut chunk_start, mut chunk_first) =
                (self.position, self.position, 0);
            for record in 0..element.count {
                position = end_of(position, record)?;
                if record + 1 - chunk_first == per_chunk || record + 1 == element.count {
                    located.chunks.push(chunk_start..position);
                    located.first_records.push(chunk_first);
                    (chunk_start, chunk_first) = (position, record + 1);
                }
            }
            Ok(position)
        };
        let bytes = self.bytes;
        let end = match self.encoding {
            BodyEncoding::Ascii => {
                // One record a line.
                let end = walk(&mut located, &mut |position, record| {
                    if position >= bytes.len() {
                        return Err(missing(record));
                    }
                    Ok(memchr::memchr(b'\n', &bytes[position..])
                        .map_or(bytes.len(), |offset| position + offset + 1))
                })?;
                self.line += element.count;
                end
            }
            BodyEncoding::Binary { big_endian } => {
                let fixed_size: Option<usize> = (element.properties.values())
                    .map(|p| match &p.data_type {
                        PropertyType::Scalar(kind) => Some(size_of_scalar(kind)),
                        PropertyType::List(..) => None,
                    })
                    .sum();
                match fixed_size {
                    // Records without properties have nothing to decode (and a
                    // count in the billions would make as many empty chunks).
                    Some(0) => self.position,
                    Some(size) => {
                        // The chunks are arithmetic.
                        let left = bytes.len() - self.position;
                        if left / size < element.count {
                            return Err(missing(left / size));
                        }
                        for first in (0..element.count).step_by(per_chunk) {
                            let start = self.position + first * size;
                            let records = per_chunk.min(element.count - first);
                            located.chunks.push(start..start + records * size);
                            located.first_records.push(first);
                        }
                        self.position + element.count * size
                    }
                    None => walk(&mut located, &mut |mut position, record| {
                        // One pass over the list counts.
                        for (name, property) in &element.properties {
                            let size = match &property.data_type {
                                PropertyType::Scalar(kind) => size_of_scalar(kind),
                                PropertyType::List(count_kind, item) => {
                                    let count = binary_list_count(
                                        &bytes[position..],
                                        count_kind,
                                        big_endian,
                                    )
                                    .map_err(|e| match e {
                                        FieldError::EndOfFile => missing(record),
                                        other => binary_error(element, record, name, other),
                                    })?;
                                    count
                                        .saturating_mul(size_of_scalar(item))
                                        .saturating_add(size_of_scalar(count_kind))
                                }
                            };
                            if bytes.len() - position < size {
                                return Err(missing(record));
                            }
                            position += size;
                        }
                        Ok(position)
                    })?,
                }
            }
        };
        self.position = end;
        Ok(located)
    }
}

/// Why a field could not be read.
#[derive(Debug)]
enum FieldError {
    EndOfFile,
    Invalid(String),
}

/// A chunk's records, one at a time, and the current record's fields in order.
struct Records<'a> {
    bytes: &'a [u8],
    position: usize,
    encoding: BodyEncoding,
    element: &'a ElementDef,
    /// The number (in its element) of the current record, and of the next.
    record: usize,
    next: usize,
    first_line: usize,
    /// ASCII: the current line's values, and the next to read.
    tokens: Vec<&'a [u8]>,
    next_token: usize,
}

impl<'a> Records<'a> {
    /// Moves to the next record; false after the last.
    fn next_record(&mut self) -> Result<bool, ReadError> {
        if self.position >= self.bytes.len() {
            return Ok(false);
        }
        self.record = self.next;
        self.next += 1;
        if self.encoding == BodyEncoding::Ascii {
            let rest = &self.bytes[self.position..];
            let length = memchr::memchr(b'\n', rest).map_or(rest.len(), |n| n + 1);
            self.position += length;
            self.next_token = 0;
            if let Err(message) = ascii_tokens(&rest[..length], &mut self.tokens) {
                return Err(self.error(FieldError::Invalid(message), None));
            }
        }
        Ok(true)
    }

    /// The current record's next field, a scalar of type `kind`, as f64
    /// (exact for every PLY type).
    fn scalar(&mut self, name: &str, kind: &ScalarType) -> Result<f64, ReadError> {
        self.value(kind).map_err(|e| self.error(e, Some(name)))
    }

    /// The current record's next field, a list: `each` gets its values.
    fn list(
        &mut self,
        name: &str,
        data_type: &PropertyType,
        mut each: impl FnMut(f64) -> Result<(), ReadError>,
    ) -> Result<(), ReadError> {
        let PropertyType::List(count_kind, item) = data_type else {
            unreachable!("a list property");
        };
        let count = match self.encoding {
            BodyEncoding::Ascii => self.token().and_then(parse_ascii::<usize>),
            BodyEncoding::Binary { big_endian } => {
                let count = binary_list_count(&self.bytes[self.position..], count_kind, big_endian);
                self.position += size_of_scalar(count_kind);
                count
            }
        }
        .map_err(|e| self.error(e, Some(name)))?;
        for _ in 0..count {
            let value = self.value(item).map_err(|e| self.error(e, Some(name)))?;
            each(value)?;
        }
        Ok(())
    }

    fn token(&mut self) -> Result<&'a [u8], FieldError> {
        let token = self.tokens.get(self.next_token).copied().ok_or_else(|| {
            FieldError::Invalid("the line has fewer values than the element has properties".into())
        })?;
        self.next_token += 1;
        Ok(token)
    }

    fn value(&mut self, kind: &ScalarType) -> Result<f64, FieldError> {
        match self.encoding {
            BodyEncoding::Ascii => {
                let token = self.token()?;
                match kind {
                    ScalarType::Char => parse_ascii::<i8>(token).map(f64::from),
                    ScalarType::UChar => parse_ascii::<u8>(token).map(f64::from),
                    ScalarType::Short => parse_ascii::<i16>(token).map(f64::from),
                    ScalarType::UShort => parse_ascii::<u16>(token).map(f64::from),
                    ScalarType::Int => parse_ascii::<i32>(token).map(f64::from),
                    ScalarType::UInt => parse_ascii::<u32>(token).map(f64::from),
                    ScalarType::Float => parse_ascii::<f32>(token).map(f64::from),
                    ScalarType::Double => parse_ascii::<f64>(token),
                }
            }
            BodyEncoding::Binary { big_endian } => {
                let value = binary_scalar(&self.bytes[self.position..], kind, big_endian)?;
                self.position += size_of_scalar(kind);
                Ok(value)
            }
        }
    }

    /// A field's error, with the record (and, ASCII, the line) it is in.
    fn error(&self, error: FieldError, property: Option<&str>) -> ReadError {
        let reason = match error {
            FieldError::EndOfFile => "unexpected end of file".to_string(),
            FieldError::Invalid(reason) => reason,
        };
        let property = property.map_or(String::new(), |name| format!(", property `{name}`"));
        let place = match self.encoding {
            BodyEncoding::Ascii => format!("line {}: ", self.first_line + self.record),
            BodyEncoding::Binary { .. } => String::new(),
        };
        ReadError::Parse(format!(
            "{place}element `{}` {}{property}: {reason}",
            self.element.name, self.record
        ))
    }
}

fn binary_error(element: &ElementDef, record: usize, name: &str, error: FieldError) -> ReadError {
    let reason = match error {
        FieldError::EndOfFile => "unexpected end of file".to_string(),
        FieldError::Invalid(reason) => reason,
    };
    ReadError::Parse(format!(
        "element `{}` {record}, property `{name}`: {reason}",
        element.name
    ))
}

/// Splits an ASCII record's line into its values, checking each against the
/// grammar of numbers (see the module documentation).
fn ascii_tokens<'a>(line: &'a [u8], tokens: &mut Vec<&'a [u8]>) -> Result<(), String> {
    tokens.clear();
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    for token in line.split(|&b| b == b' ' || b == b'\t') {
        if token.is_empty() {
            continue;
        }
        if !is_ascii_number(token) {
            return Err(format!(
                "`{}` is not a number",
                String::from_utf8_lossy(token)
            ));
        }
        tokens.push(token);
    }
    Ok(())
}

/// `[-+]?[0-9]+(\.[0-9]+)?([eE][-+]?[0-9]+)?`, the numbers ply-rs-bw's grammar reads.
fn is_ascii_number(token: &[u8]) -> bool {
    fn digits(bytes: &[u8], at: &mut usize) -> bool {
        let start = *at;
        while bytes.get(*at).is_some_and(u8::is_ascii_digit) {
            *at += 1;
        }
        *at > start
    }
    let mut at = usize::from(matches!(token.first(), Some(b'-' | b'+')));
    if !digits(token, &mut at) {
        return false;
    }
    if token.get(at) == Some(&b'.') {
        at += 1;
        if !digits(token, &mut at) {
            return false;
        }
    }
    if matches!(token.get(at), Some(b'e' | b'E')) {
        at += 1;
        at += usize::from(matches!(token.get(at), Some(b'-' | b'+')));
        if !digits(token, &mut at) {
            return false;
        }
    }
    at == token.len()
}

fn parse_ascii<T: std::str::FromStr>(token: &[u8]) -> Result<T, FieldError> {
    // Checked by `is_ascii_number`: ASCII only.
    let text = std::str::from_utf8(token).unwrap_or_default();
    text.parse().map_err(|_| {
        FieldError::Invalid(format!("`{text}` is not a {}", std::any::type_name::<T>()))
    })
}

pub fn size_of_scalar(kind: &ScalarType) -> usize {
    match kind {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// A binary scalar at the start of `bytes`, as f64 (exact for every PLY type).
fn binary_scalar(bytes: &[u8], kind: &ScalarType, big_endian: bool) -> Result<f64, FieldError> {
    fn read<const N: usize>(bytes: &[u8], big_endian: bool) -> Result<[u8; N], FieldError> {
        let mut array: [u8; N] = bytes
            .get(..N)
            .and_then(|b| b.try_into().ok())
            .ok_or(FieldError::EndOfFile)?;
        // Bytes in little-endian order, for `from_le_bytes`.
        if big_endian {
            array.reverse();
        }
        Ok(array)
    }
    Ok(match kind {
        ScalarType::Char => f64::from(i8::from_le_bytes(read(bytes, big_endian)?)),
        ScalarType::UChar => f64::from(u8::from_le_bytes(read(bytes, big_endian)?)),
        ScalarType::Short => f64::from(i16::from_le_bytes(read(bytes, big_endian)?)),
        ScalarType::UShort => f64::from(u16::from_le_bytes(read(bytes, big_endian)?)),
        ScalarType::Int => f64::from(i32::from_le_bytes(read(bytes, big_endian)?)),
        ScalarType::UInt => f64::from(u32::from_le_bytes(read(bytes, big_endian)?)),
        ScalarType::Float => f64::from(f32::from_le_bytes(read(bytes, big_endian)?)),
        ScalarType::Double => f64::from_le_bytes(read(bytes, big_endian)?),
    })
}

/// A binary list's length at the start of `bytes`: an integer, not negative.
fn binary_list_count(
    bytes: &[u8],
    kind: &ScalarType,
    big_endian: bool,
) -> Result<usize, FieldError> {
    if matches!(kind, ScalarType::Float | ScalarType::Double) {
        return Err(FieldError::Invalid(format!(
            "a list's length must be an integer type, not {kind:?}"
        )));
    }
    let count = binary_scalar(bytes, kind, big_endian)?;
    if count < 0.0 {
        return Err(FieldError::Invalid(format!(
            "a list's length cannot be negative ({count})"
        )));
    }
    Ok(count as usize)
}

//! `sort` and `sortByKey` on the device: a least-significant-digit radix
//! sort of the keys' ordered bits (the CPU's `order_bits`, so both backends
//! agree bit for bit) carrying each key's position, then one gather of the
//! keys and values by those positions.
//!
//! Each digit pass is three steps that need no forward progress between
//! workgroups, only the order of dispatches: every invocation counts the
//! digits of its block of `SORT_BLOCK` elements; an exclusive scan of the
//! counts, laid out digit by digit and block by block, gives each block's
//! first slot for each digit (the `scan` kernels); every invocation walks
//! its block again in order and writes each element at its digit's next
//! slot. Blocks and elements keep their order within a digit, so each pass is
//! stable, and so is the sort.

use super::{Dispatch, BLOCK};
use crate::array::{allocate_array, GpuArray};
use crate::backend::GpuBackend;
use dpp_runtime::interpret::RunError;
use dpp_runtime::monoid::MonoidOp;
use dpp_runtime::types::ElemType;
use std::fmt::Write;

/// Bits per digit: 16 counters per invocation stay in registers.
const DIGIT_BITS: u32 = 4;
const DIGITS: u32 = 1 << DIGIT_BITS;
/// Elements per invocation in the counting and moving passes.
const SORT_BLOCK: usize = BLOCK;

/// WGSL for the CPU's `order_bits` and its inverse, by key type.
fn order_functions(key_type: ElemType) -> &'static str {
    match key_type {
        ElemType::I32 => {
            "fn sort_order(b: u32) -> u32 { return b ^ 0x80000000u; }\n\
             fn sort_unorder(o: u32) -> u32 { return o ^ 0x80000000u; }\n"
        }
        ElemType::F32 => {
            "fn sort_order(b: u32) -> u32 { return select(b ^ 0x80000000u, ~b, (b & 0x80000000u) != 0u); }\n\
             fn sort_unorder(o: u32) -> u32 { return select(o ^ 0x80000000u, ~o, (o & 0x80000000u) == 0u); }\n"
        }
        _ => {
            "fn sort_order(b: u32) -> u32 { return b; }\n\
             fn sort_unorder(o: u32) -> u32 { return o; }\n"
        }
    }
}

/// Where a digit pass reads its keys and positions: the input itself (the
/// first pass), or the previous pass's output.
enum PassSource<'a> {
    Input(&'a GpuArray),
    Sorted {
        keys: &'a GpuArray,
        positions: &'a GpuArray,
    },
}

/// What [`GpuBackend::block_kernel`] prepares.
struct BlockKernel<'b> {
    builder: crate::shader::ShaderBuilder<'b>,
    /// Element `j`'s ordered key bits and original position.
    key: String,
    position: String,
    /// The digit of `key` this pass sorts by.
    digit: String,
    /// The number of blocks.
    block_count: String,
    /// `start` and `end`: the block's elements.
    prologue: String,
}

impl GpuBackend<'_> {
    /// Sorts `keys` (u32, i32 or f32) and moves `values` with them; returns
    /// the sorted keys and values.
    pub(super) fn sort(
        &self,
        keys: &GpuArray,
        values: Option<&GpuArray>,
        dispatches: &mut Vec<Dispatch>,
    ) -> Result<(GpuArray, Option<GpuArray>), RunError> {
        let records = &self.library.records;
        let n = keys.len;
        let allocate = |ty: ElemType, len: usize| {
            allocate_array(self.gpu, ty, len, records, &self.buffers).map_err(RunError::from)
        };
        let sorted_keys = allocate(keys.ty, n)?;
        let sorted_values = values.map(|v| allocate(v.ty, n)).transpose()?;
        if n == 0 {
            return Ok((sorted_keys, sorted_values));
        }
        let blocks = n.div_ceil(SORT_BLOCK);
        let counts = allocate(ElemType::U32, DIGITS as usize * blocks)?;
        // Ordered keys and positions, ping-ponged between the passes.
        let buffers = [
            (allocate(ElemType::U32, n)?, allocate(ElemType::U32, n)?),
            (allocate(ElemType::U32, n)?, allocate(ElemType::U32, n)?),
        ];
        let passes = u32::BITS / DIGIT_BITS;
        for pass in 0..passes {
            let source = match pass {
                0 => PassSource::Input(keys),
                _ => {
                    let (keys, positions) = &buffers[(pass as usize + 1) % 2];
                    PassSource::Sorted { keys, positions }
                }
            };
            let (keys_out, positions_out) = &buffers[pass as usize % 2];
            let shift = pass * DIGIT_BITS;
            dispatches.push(self.count_digits(&source, &counts, shift, n, blocks));
            let starts = self.scan(MonoidOp::Add, false, &counts, None, dispatches)?;
            dispatches.push(self.move_by_digit(
                &source,
                &starts,
                (keys_out, positions_out),
                shift,
                n,
                blocks,
            ));
        }
        let (ordered, positions) = &buffers[(passes as usize + 1) % 2];
        dispatches.push(self.sorted_gather(
            keys.ty,
            (ordered, positions),
            (&sorted_keys, values.zip(sorted_values.as_ref())),
            n,
        ));
        Ok((sorted_keys, sorted_values))
    }

    /// A kernel over the blocks of a digit pass: its builder, the source's
    /// key (ordered bits) and position of element `j`, and the parameters
    /// every block reads, as WGSL expressions.
    fn block_kernel(
        &self,
        source: &PassSource<'_>,
        shift: u32,
        n: usize,
        blocks: usize,
    ) -> BlockKernel<'_> {
        let mut builder = self.builder();
        let (key, position) = match source {
            PassSource::Input(keys) => {
                builder.functions.push_str(order_functions(keys.ty));
                let load = builder.array_loader(keys);
                (format!("sort_order(bitcast<u32>({load}(j)))"), "j".into())
            }
            PassSource::Sorted { keys, positions } => (
                format!("{}(j)", builder.array_loader(keys)),
                format!("{}(j)", builder.array_loader(positions)),
            ),
        };
        let count = builder.param_u32(n as u32);
        let block_count = builder.param_u32(blocks as u32);
        let shift = builder.param_u32(shift);
        let prologue = format!(
            "    let start = i * {SORT_BLOCK}u;\n    let end = min(start + {SORT_BLOCK}u, {count});\n"
        );
        BlockKernel {
            builder,
            digit: format!("(key >> {shift}) & {}u", DIGITS - 1),
            key,
            position,
            block_count,
            prologue,
        }
    }

    /// Pass 1 of a digit: each block's count of each digit, at
    /// `counts[digit * blocks + block]`.
    fn count_digits(
        &self,
        source: &PassSource<'_>,
        counts: &GpuArray,
        shift: u32,
        n: usize,
        blocks: usize,
    ) -> Dispatch {
        let BlockKernel {
            mut builder,
            key,
            digit,
            block_count,
            prologue,
            ..
        } = self.block_kernel(source, shift, n, blocks);
        let store = builder.array_store(counts, &format!("d * {block_count} + i"), "tally[d]");
        let _ = write!(
            builder.body,
            "{prologue}\
             \x20   var tally: array<u32, {DIGITS}>;\n\
             \x20   for (var j = start; j < end; j++) {{\n\
             \x20       let key = {key};\n\
             \x20       let d = {digit};\n\
             \x20       tally[d] += 1u;\n\
             \x20   }}\n\
             \x20   for (var d = 0u; d < {DIGITS}u; d++) {{ {store} }}\n"
        );
        self.dispatch_of(builder, blocks)
    }

    /// Pass 3 of a digit: each block's elements, in order, to their digit's
    /// next slot, from the block's starts that the scan of the counts gave.
    fn move_by_digit(
        &self,
        source: &PassSource<'_>,
        starts: &GpuArray,
        (keys_out, positions_out): (&GpuArray, &GpuArray),
        shift: u32,
        n: usize,
        blocks: usize,
    ) -> Dispatch {
        let BlockKernel {
            mut builder,
            key,
            position,
            digit,
            block_count,
            prologue,
        } = self.block_kernel(source, shift, n, blocks);
        let start_of = builder.array_loader(starts);
        let store_key = builder.array_store(keys_out, "slot", "key");
        let store_position = builder.array_store(positions_out, "slot", &position);
        let _ = write!(
            builder.body,
            "{prologue}\
             \x20   var next: array<u32, {DIGITS}>;\n\
             \x20   for (var d = 0u; d < {DIGITS}u; d++) {{ next[d] = {start_of}(d * {block_count} + i); }}\n\
             \x20   for (var j = start; j < end; j++) {{\n\
             \x20       let key = {key};\n\
             \x20       let d = {digit};\n\
             \x20       let slot = next[d];\n\
             \x20       next[d] = slot + 1u;\n\
             \x20       {store_key}        {store_position}\
             \x20   }}\n"
        );
        self.dispatch_of(builder, blocks)
    }

    /// The sorted keys back in their own type, and the values moved to
    /// their keys' places.
    fn sorted_gather(
        &self,
        key_type: ElemType,
        (ordered, positions): (&GpuArray, &GpuArray),
        (sorted_keys, values): (&GpuArray, Option<(&GpuArray, &GpuArray)>),
        n: usize,
    ) -> Dispatch {
        let mut builder = self.builder();
        builder.functions.push_str(order_functions(key_type));
        let ordered = builder.array_loader(ordered);
        let key = match key_type {
            ElemType::I32 => "bitcast<i32>(bits)",
            ElemType::F32 => "bitcast<f32>(bits)",
            _ => "bits",
        };
        let store_key = builder.array_store(sorted_keys, "i", key);
        let _ = write!(
            builder.body,
            "    let bits = sort_unorder({ordered}(i));\n    {store_key}"
        );
        if let Some((values, sorted_values)) = values {
            let position = builder.array_loader(positions);
            let load = builder.array_loader(values);
            let store = builder.array_store(sorted_values, "i", "value");
            let _ = write!(
                builder.body,
                "    let value = {load}({position}(i));\n    {store}"
            );
        }
        self.dispatch_of(builder, n)
    }
}

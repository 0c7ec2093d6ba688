//! The sides of `select`s that a block of lanes may skip: `select(c, a, b)`
//! discards `a` wherever `c` is false, so where no lane of a block holds `c`
//! the steps that only `a` reads need not run, and the same for `b` where
//! every lane holds `c`. That is what a functor does with a branch (the
//! `shader` skips a miss, and a light behind the point) and what a compiled
//! run otherwise pays for on every lane. The results are the same bits: a
//! skipped value is one the select would have discarded.
//!
//! Only steps that cannot fail are skipped (element-wise maps other than an
//! integer division, and field reads): a gather checks its index and an
//! integer division its divisor on every element, discarded or not, as the
//! column run does, so that bad input fails the same way in both.

use super::{Segment, SegmentStep};
use crate::types::ElemType;
use std::collections::{HashMap, HashSet};

/// One select's side that a block may skip.
#[derive(Debug, PartialEq, Eq)]
pub(super) struct SkippableSide {
    /// `true`: the value taken where the condition holds (skipped where no
    /// lane holds it); `false`: the other (skipped where every lane does).
    pub(super) taken_where_true: bool,
    /// The side's value.
    pub(super) value: u32,
    /// The positions of the steps only this side reads, in order.
    pub(super) steps: Vec<usize>,
}

/// A segment's skippable sides, and which select emits each of their steps.
#[derive(Debug, Default)]
pub(super) struct SkippableSides {
    /// By the select's position.
    pub(super) sides: HashMap<usize, SkippableSide>,
    /// Each skippable step's innermost select (a side may hold whole selects
    /// with sides of their own): that select emits it.
    pub(super) emitted_by: HashMap<usize, usize>,
}

/// The skippable sides of `segment`'s selects. `same_loop(k, p)` says
/// whether step `k` runs in the same loop as the select at `p` (a fan-out's
/// point steps run before its items' loop: they stay where they are).
pub(super) fn find(segment: &Segment, same_loop: impl Fn(usize, usize) -> bool) -> SkippableSides {
    let mut found = SkippableSides::default();
    for (position, step) in segment.steps.iter().enumerate() {
        let SegmentStep::Map {
            functor, inputs, ..
        } = step
        else {
            continue;
        };
        let [(condition, _), (when_true, _), (when_false, _)] = inputs[..] else {
            continue;
        };
        if functor != "select" {
            continue;
        }
        let side = [
            (true, when_true, when_false),
            (false, when_false, when_true),
        ]
        .into_iter()
        .filter(|&(_, value, other)| value != condition && value != other)
        .map(|(taken_where_true, value, _)| SkippableSide {
            taken_where_true,
            value,
            steps: only_read_by(segment, position, value, &same_loop),
        })
        .find(|side| !side.steps.is_empty());
        if let Some(side) = side {
            found.sides.insert(position, side);
        }
    }
    // Innermost last, so that its claim stands.
    let mut selects: Vec<_> = found.sides.keys().copied().collect();
    selects.sort_unstable_by(|a, b| b.cmp(a));
    for select in selects {
        for &step in &found.sides[&select].steps {
            found.emitted_by.insert(step, select);
        }
    }
    found
}

/// The steps before the select at `select` whose values only it reads, as
/// its input `value`, directly or through each other.
fn only_read_by(
    segment: &Segment,
    select: usize,
    value: u32,
    same_loop: impl Fn(usize, usize) -> bool,
) -> Vec<usize> {
    let mut inside: HashSet<u32> = HashSet::new();
    let mut steps = Vec::new();
    for position in (0..select).rev() {
        let step = &segment.steps[position];
        let output = step.output().0;
        if !cannot_fail(step)
            || !same_loop(position, select)
            || segment.outputs.iter().any(|(v, _)| v.0 == output)
        {
            continue;
        }
        let mut readers = segment
            .steps
            .iter()
            .enumerate()
            .filter(|(_, reader)| reader.reads().contains(&output))
            .peekable();
        if readers.peek().is_none() {
            continue;
        }
        let only_inside = readers.all(|(at, reader)| match at == select {
            true => output == value,
            false => inside.contains(&reader.output().0),
        });
        if only_inside {
            inside.insert(output);
            steps.push(position);
        }
    }
    steps.reverse();
    steps
}

fn cannot_fail(step: &SegmentStep) -> bool {
    match step {
        SegmentStep::Map {
            functor, inputs, ..
        } => {
            let integer = matches!(inputs[0].1, ElemType::U32 | ElemType::I32);
            !(integer && matches!(functor.as_str(), "div" | "rem"))
        }
        SegmentStep::Field { .. } => true,
        SegmentStep::Iota { .. } | SegmentStep::Fill { .. } | SegmentStep::Gather { .. } => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compile::ir::VarId;

    fn map(functor: &str, inputs: &[(u32, ElemType)], output: u32) -> SegmentStep {
        SegmentStep::Map {
            functor: functor.into(),
            inputs: inputs.to_vec(),
            output_type: ElemType::F32,
            named: Vec::new(),
            output: VarId(output),
        }
    }

    /// `0 = iota`, `1 = fill`, `2 = 0 < 1`, `3 = toF32(0)`, then `rest`.
    fn steps_after_a_condition(rest: Vec<SegmentStep>) -> Vec<SegmentStep> {
        use ElemType::U32;
        let mut steps = vec![
            SegmentStep::Iota { output: VarId(0) },
            SegmentStep::Fill {
                fill: 0,
                output: VarId(1),
            },
            map("lt", &[(0, U32), (1, U32)], 2),
            map("toF32", &[(0, U32)], 3),
        ];
        steps.extend(rest);
        steps
    }

    fn segment(steps: Vec<SegmentStep>, outputs: &[u32]) -> Segment {
        Segment {
            ops: 0..steps.len(),
            elementwise: Vec::new(),
            gathered: vec![(VarId(100), ElemType::F32)],
            outputs: outputs.iter().map(|&v| (VarId(v), ElemType::F32)).collect(),
            fills: vec![ElemType::U32],
            steps,
        }
    }

    /// A side's steps are those only it reads, through each other; a value
    /// also read elsewhere, a gather and an integer division stay outside;
    /// an inner select's side is emitted by the inner select.
    #[test]
    fn a_side_holds_the_steps_only_it_reads() {
        use ElemType::{Bool, F32, U32};
        let steps = steps_after_a_condition(vec![
            map("sqrt", &[(3, F32)], 4),
            SegmentStep::Gather {
                index: 0,
                gathered: 0,
                output: VarId(5),
            },
            map("div", &[(0, U32), (1, U32)], 6),
            map("toF32", &[(6, U32)], 7),
            // 8 = 4 * 5 + 7: the side's own value.
            map("mul", &[(4, F32), (5, F32)], 8),
            map("add", &[(8, F32), (7, F32)], 9),
            // An inner select inside the outer one's side.
            map("exp", &[(3, F32)], 10),
            map("select", &[(2, Bool), (10, F32), (3, F32)], 11),
            map("add", &[(9, F32), (11, F32)], 12),
            map("select", &[(2, Bool), (12, F32), (3, F32)], 13),
            // Skippable where every lane takes the condition's side.
            map("abs", &[(3, F32)], 14),
            map("select", &[(2, Bool), (3, F32), (14, F32)], 15),
        ]);
        let found = find(&segment(steps, &[13, 15]), |_, _| true);
        let inner = &found.sides[&11];
        assert_eq!((inner.taken_where_true, inner.value), (true, 10));
        assert_eq!(inner.steps, [10]);
        let outer = &found.sides[&13];
        assert_eq!((outer.taken_where_true, outer.value), (true, 12));
        // Not 3 (read by both sides), 5 (a gather), 6 (an integer division).
        assert_eq!(outer.steps, [4, 7, 8, 9, 10, 11, 12]);
        let other = &found.sides[&15];
        assert_eq!((other.taken_where_true, other.value), (false, 14));
        assert_eq!(other.steps, [14]);
        assert_eq!(found.emitted_by[&10], 11);
        assert_eq!(found.emitted_by[&11], 13);
        assert_eq!(found.emitted_by[&14], 15);
    }

    /// A value the segment stores, or that a step outside another loop
    /// (a fan-out's point steps) makes, is not skipped.
    #[test]
    fn stored_values_and_other_loops_stay() {
        use ElemType::{Bool, F32};
        let steps = || {
            steps_after_a_condition(vec![
                map("sqrt", &[(3, F32)], 4),
                map("exp", &[(4, F32)], 5),
                map("select", &[(2, Bool), (5, F32), (3, F32)], 6),
            ])
        };
        let all = find(&segment(steps(), &[6]), |_, _| true);
        assert_eq!(all.sides[&6].steps, [4, 5]);
        let stored = find(&segment(steps(), &[4, 6]), |_, _| true);
        assert_eq!(stored.sides[&6].steps, [5]);
        let other_loop = find(&segment(steps(), &[6]), |k, _| k != 4);
        assert_eq!(other_loop.sides[&6].steps, [5]);
    }
}

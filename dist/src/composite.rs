//! The executor: walks a [`Plan`] with MPI point-to-point messages, calls the
//! caller's blend in the plan's order, and gathers the finished regions on
//! rank 0.
//!
//! Each round posts all of its receives and sends at once (non-blocking) and
//! waits for all of them, so no pair of ranks can deadlock on message order
//! whatever the group size. A blend that fails mid-schedule does *not* end
//! the rank: it keeps serving its partners (with its unblended piece, of the
//! right size, and calls the blend no more) until the rounds end, and then
//! the ranks agree on failure ([`Ranks::agree`]) so that every rank returns
//! an error and none waits forever. That costs one small collective per
//! composite and keeps the caller's error handling (exit statuses, messages)
//! in charge; [`Ranks::abort`] is left for callers that cannot continue.

use crate::ranks::Ranks;
use crate::schedule::{plan, CompositeSchedule, Source};
use crate::wire::{decode, encode_range, pixel_bytes, slice_columns, take};
use dpp_runtime::interpret::RunError;
use dpp_runtime::{Column, ColumnView, ElemType, RecordRegistry};
use std::ops::Range;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What one round (or the gather) cost this rank.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RoundStats {
    /// Wall time of the round on this rank: messages and blends.
    pub time: Duration,
    pub bytes_sent: u64,
    pub bytes_received: u64,
}

/// What compositing cost this rank, round by round.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompositeStats {
    pub rounds: Vec<RoundStats>,
    pub gather: RoundStats,
    /// Time spent in the caller's blend, over all rounds.
    pub blend_time: Duration,
}

/// The result of [`composite`].
#[derive(Clone, Debug)]
pub struct Composited {
    /// The whole image: `Some` on rank 0 only.
    pub image: Option<Vec<Arc<Column>>>,
    pub stats: CompositeStats,
}

/// The blend callback: `(front, back) -> blended`, same types and length.
pub type Blend<'b> =
    dyn FnMut(&[Arc<Column>], &[Arc<Column>]) -> Result<Vec<Arc<Column>>, RunError> + 'b;

/// Pixels `wanted` of columns that hold pixels `held`.
fn relative(held: &Range<usize>, wanted: &Range<usize>) -> Range<usize> {
    if wanted.is_empty() {
        0..0
    } else {
        wanted.start - held.start..wanted.end - held.start
    }
}

/// The local checks every composite makes before talking: a description of
/// the set-up to compare across ranks, or what is wrong.
fn describe(
    fragments: &[Arc<Column>],
    order: Option<(&[usize], usize)>,
    what: &str,
) -> Result<(usize, Vec<ElemType>, String), RunError> {
    let Some(first) = fragments.first() else {
        return Err(RunError::bad_input(format!("{what}: no fragment arrays")));
    };
    let n = first.len();
    if let Some(column) = fragments.iter().find(|c| c.len() != n) {
        return Err(RunError::bad_input(format!(
            "{what}: fragment arrays of different lengths ({n} and {})",
            column.len()
        )));
    }
    let types: Vec<ElemType> = fragments.iter().map(|c| c.elem_type()).collect();
    if let Some((order, p)) = order {
        let mut seen = vec![false; p];
        let permutation = order.len() == p
            && order
                .iter()
                .all(|&r| r < p && !std::mem::replace(&mut seen[r], true));
        if !permutation {
            return Err(RunError::bad_input(format!(
                "{what}: the order {order:?} is not a permutation of the {p} ranks"
            )));
        }
    }
    let description = format!("{n} pixels of {types:?}, order {order:?}");
    Ok((n, types, description))
}

/// Sends and receives one round's messages: all posted at once, then all
/// awaited.
fn exchange(
    ranks: &Ranks,
    tag: i32,
    sends: &[(usize, Vec<u8>)],
    receives: &mut [(usize, Vec<u8>)],
) -> Result<(), RunError> {
    if sends.is_empty() && receives.is_empty() {
        return Ok(());
    }
    #[cfg(feature = "mpi")]
    if let Some(comm) = ranks.communicator() {
        use mpi::traits::{Communicator, Destination, Source};
        mpi::request::scope(|scope| {
            let mut requests = Vec::with_capacity(sends.len() + receives.len());
            for (peer, buffer) in receives.iter_mut() {
                requests.push(
                    comm.process_at_rank(*peer as mpi::Rank)
                        .immediate_receive_into_with_tag(scope, &mut buffer[..], tag),
                );
            }
            for (peer, buffer) in sends {
                requests.push(
                    comm.process_at_rank(*peer as mpi::Rank)
                        .immediate_send_with_tag(scope, &buffer[..], tag),
                );
            }
            for request in requests {
                request.wait();
            }
        });
        return Ok(());
    }
    let _ = (ranks, tag);
    Err(RunError::internal(
        "a single rank has no one to exchange pixels with",
    ))
}

/// A message must fit MPI's `int` count of bytes.
fn check_message_size(pixels: usize, bytes_per_pixel: usize) -> Result<(), RunError> {
    let bytes = pixels as u128 * bytes_per_pixel as u128;
    if bytes > i32::MAX as u128 {
        return Err(RunError::resource_limit(format!(
            "a compositing message of {bytes} bytes is over MPI's 2 GiB limit; use more ranks or a smaller image"
        )));
    }
    Ok(())
}

/// Composites every rank's per-pixel arrays (`fragments`, all of length n)
/// so that rank 0 holds the left fold of `blend(front, back)` over the ranks
/// in `order` (front to back; `0..p` for depth compositing). A collective:
/// every rank calls it with the same schedule, order, pixel count and
/// element types (checked: a difference is a BadInput error on every rank).
/// With one rank the fragments come back unchanged and `blend` is never
/// called. If a blend fails on any rank, every rank returns an error (see
/// the module's doc for why the ranks finish the rounds first).
pub fn composite(
    ranks: &Ranks,
    schedule: &CompositeSchedule,
    fragments: Vec<Arc<Column>>,
    order: &[usize],
    records: &RecordRegistry,
    blend: &mut Blend<'_>,
) -> Result<Composited, RunError> {
    let p = ranks.size();
    let (n, types, description) =
        ranks.agree(describe(&fragments, Some((order, p)), "compositing"))?;
    if p == 1 {
        return Ok(Composited {
            image: Some(fragments),
            stats: CompositeStats::default(),
        });
    }
    ranks.same_on_every_rank(
        "the compositing set-up (schedule, pixels, element types, order)",
        format!("{schedule}: {description}").as_bytes(),
    )?;
    let bytes_per_pixel = pixel_bytes(&types, records);
    // Same numbers on every rank, so every rank returns this error alike.
    check_message_size(n, bytes_per_pixel)?;

    let plan = plan(schedule, p, n, order);
    let me = ranks.rank();
    let mut stats = CompositeStats::default();
    let mut held_range = 0..n;
    let mut held = fragments;
    let mut failure: Option<RunError> = None;
    for (index, round) in plan.rounds.iter().enumerate() {
        let step = &round[me];
        let started = Instant::now();
        let sends: Vec<(usize, Vec<u8>)> = step
            .sends
            .iter()
            .map(|t| {
                (
                    t.peer,
                    encode_range(&held, relative(&held_range, &t.pixels)),
                )
            })
            .collect();
        let mut receives: Vec<(usize, Vec<u8>)> = step
            .receives
            .iter()
            .map(|t| (t.peer, vec![0u8; t.pixels.len() * bytes_per_pixel]))
            .collect();
        exchange(ranks, index as i32, &sends, &mut receives)?;
        let mut round_stats = RoundStats {
            bytes_sent: sends.iter().map(|(_, b)| b.len() as u64).sum(),
            bytes_received: receives.iter().map(|(_, b)| b.len() as u64).sum(),
            ..RoundStats::default()
        };
        drop(sends);

        let own = slice_columns(&held, relative(&held_range, &step.keep));
        let keep_len = step.keep.len();
        let mut acc: Option<Vec<Arc<Column>>> = None;
        for source in &step.blend {
            let piece = match source {
                Source::Own => own.clone(),
                Source::From(peer) => {
                    let (_, bytes) = receives
                        .iter()
                        .find(|(from, _)| from == peer)
                        .expect("the plan receives what it blends");
                    match decode(&types, keep_len, bytes, records) {
                        Ok(piece) => piece,
                        Err(error) => {
                            failure.get_or_insert(error.within(format!("from rank {peer}")));
                            own.clone()
                        }
                    }
                }
            };
            acc = Some(match acc {
                None => piece,
                Some(front) if failure.is_some() => front,
                Some(front) => {
                    let blending = Instant::now();
                    let result = blend(&front, &piece).and_then(|out| {
                        let fits = out.len() == types.len()
                            && out
                                .iter()
                                .zip(&types)
                                .all(|(c, ty)| c.elem_type() == *ty && c.len() == keep_len);
                        if fits {
                            Ok(out)
                        } else {
                            Err(RunError::internal(
                                "the blend returned arrays of other types or lengths than it was given",
                            ))
                        }
                    });
                    stats.blend_time += blending.elapsed();
                    match result {
                        Ok(out) => out,
                        Err(error) => {
                            failure.get_or_insert(error);
                            front
                        }
                    }
                }
            });
        }
        held = acc.unwrap_or(own);
        held_range = step.keep.clone();
        round_stats.time = started.elapsed();
        stats.rounds.push(round_stats);
    }
    ranks.agree(failure.map_or(Ok(()), Err))?;

    // The gather: every rank's finished region to rank 0.
    let started = Instant::now();
    let tag = plan.rounds.len() as i32;
    let mine = &plan.owned[me];
    let mut sends = Vec::new();
    let mut receives = Vec::new();
    if me == 0 {
        for (rank, region) in plan.owned.iter().enumerate().skip(1) {
            if !region.is_empty() {
                receives.push((rank, vec![0u8; region.len() * bytes_per_pixel]));
            }
        }
    } else if !mine.is_empty() {
        sends.push((0, encode_range(&held, relative(&held_range, mine))));
    }
    exchange(ranks, tag, &sends, &mut receives)?;
    stats.gather.bytes_sent = sends.iter().map(|(_, b)| b.len() as u64).sum();
    stats.gather.bytes_received = receives.iter().map(|(_, b)| b.len() as u64).sum();
    let image = if me == 0 {
        let mut parts: Vec<(usize, Vec<Arc<Column>>)> = Vec::with_capacity(p);
        if !mine.is_empty() {
            parts.push((
                mine.start,
                slice_columns(&held, relative(&held_range, mine)),
            ));
        }
        for (rank, bytes) in &receives {
            let region = &plan.owned[*rank];
            parts.push((region.start, decode(&types, region.len(), bytes, records)?));
        }
        parts.sort_by_key(|(start, _)| *start);
        Some(join(&types, &parts, records))
    } else {
        None
    };
    stats.gather.time = started.elapsed();
    Ok(Composited { image, stats })
}

/// Each column of `parts`, joined in order.
fn join(
    types: &[ElemType],
    parts: &[(usize, Vec<Arc<Column>>)],
    records: &RecordRegistry,
) -> Vec<Arc<Column>> {
    types
        .iter()
        .enumerate()
        .map(|(j, ty)| {
            let views: Vec<ColumnView<'_>> = parts.iter().map(|(_, cols)| cols[j].view()).collect();
            Arc::new(Column::concat_views(*ty, &views, records))
        })
        .collect()
}

/// Assembles an image decomposed by pixels: every rank rendered all pixels
/// but only those it owns (`owner(i)`, the same function on every rank) are
/// right; each rank sends just its own pixels and rank 0 puts pixel i
/// together from rank `owner(i)`. A collective; `Some` on rank 0 only.
pub fn gather_pieces(
    ranks: &Ranks,
    fragments: Vec<Arc<Column>>,
    owner: &dyn Fn(usize) -> usize,
    records: &RecordRegistry,
) -> Result<Option<Vec<Arc<Column>>>, RunError> {
    let p = ranks.size();
    let local = describe(&fragments, None, "gathering pieces").and_then(|(n, types, d)| {
        let mut owned: Vec<Vec<usize>> = vec![Vec::new(); p];
        for i in 0..n {
            let rank = owner(i);
            if rank >= p {
                return Err(RunError::bad_input(format!(
                    "gathering pieces: pixel {i}'s owner is rank {rank}, of {p} ranks"
                )));
            }
            owned[rank].push(i);
        }
        Ok((n, types, d, owned))
    });
    let (n, types, description, owned) = ranks.agree(local)?;
    if p == 1 {
        return Ok(Some(fragments));
    }
    ranks.same_on_every_rank(
        "the pieces' pixels and element types",
        description.as_bytes(),
    )?;
    let bytes_per_pixel = pixel_bytes(&types, records);
    check_message_size(n, bytes_per_pixel)?;
    let me = ranks.rank();
    let pick = |indices: &[usize]| -> Vec<Arc<Column>> {
        fragments
            .iter()
            .map(|c| Arc::new(take(&c.view(), indices)))
            .collect()
    };
    let mut sends = Vec::new();
    let mut receives = Vec::new();
    if me == 0 {
        for (rank, indices) in owned.iter().enumerate().skip(1) {
            if !indices.is_empty() {
                receives.push((rank, vec![0u8; indices.len() * bytes_per_pixel]));
            }
        }
    } else if !owned[me].is_empty() {
        let mine = pick(&owned[me]);
        sends.push((0, encode_range(&mine, 0..owned[me].len())));
    }
    exchange(ranks, 0, &sends, &mut receives)?;
    if me != 0 {
        return Ok(None);
    }
    // Rank by rank, in rank order, then put back into pixel order.
    let mut parts = vec![(0, pick(&owned[0]))];
    for (rank, bytes) in &receives {
        parts.push((*rank, decode(&types, owned[*rank].len(), bytes, records)?));
    }
    parts.sort_by_key(|(rank, _)| *rank);
    let joined = join(&types, &parts, records);
    let mut source_of = vec![0usize; n];
    for (j, &pixel) in owned.iter().flatten().enumerate() {
        source_of[pixel] = j;
    }
    Ok(Some(
        joined
            .iter()
            .map(|c| Arc::new(take(&c.view(), &source_of)))
            .collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_rank_returns_its_fragments_and_never_blends() {
        let ranks = Ranks::single();
        let fragments = vec![
            Arc::new(Column::F32(vec![1.0, 2.0])),
            Arc::new(Column::U32(vec![7, 8])),
        ];
        for schedule in [
            CompositeSchedule::DirectSend,
            CompositeSchedule::BinarySwap,
            CompositeSchedule::RadixK(8),
        ] {
            let mut blend = |_: &[Arc<Column>], _: &[Arc<Column>]| -> Result<_, RunError> {
                panic!("one rank never blends")
            };
            let out = composite(
                &ranks,
                &schedule,
                fragments.clone(),
                &[0],
                &RecordRegistry::default(),
                &mut blend,
            )
            .unwrap();
            assert_eq!(out.image, Some(fragments.clone()));
            assert!(out.stats.rounds.is_empty());
        }
        let pieces = gather_pieces(
            &ranks,
            fragments.clone(),
            &|_| 0,
            &RecordRegistry::default(),
        );
        assert_eq!(pieces, Ok(Some(fragments)));
    }

    #[test]
    fn bad_set_ups_are_bad_input() {
        let ranks = Ranks::single();
        let records = RecordRegistry::default();
        let mut blend = |f: &[Arc<Column>], _: &[Arc<Column>]| Ok(f.to_vec());
        let uneven = vec![
            Arc::new(Column::F32(vec![1.0, 2.0])),
            Arc::new(Column::U32(vec![7])),
        ];
        let schedule = CompositeSchedule::DirectSend;
        let error = composite(&ranks, &schedule, uneven, &[0], &records, &mut blend).unwrap_err();
        assert_eq!(error.kind, dpp_runtime::ErrorKind::BadInput);
        let one = vec![Arc::new(Column::F32(vec![1.0]))];
        let error =
            composite(&ranks, &schedule, one.clone(), &[1], &records, &mut blend).unwrap_err();
        assert!(error.message.contains("permutation"), "{}", error.message);
        let error = gather_pieces(&ranks, one, &|_| 1, &records).unwrap_err();
        assert_eq!(error.kind, dpp_runtime::ErrorKind::BadInput);
    }
}

//! The process's place among the ranks, and the few collectives a
//! distributed run needs. It exists so that the rest of dpp never names MPI:
//! without the `mpi` feature (or started without `mpirun`) a process is one
//! rank of size 1 and every collective is the identity, so the same code
//! path serves a laptop and a cluster.
//!
//! Every method is a *collective*: every rank must call the same methods in
//! the same order, or the ranks wait for each other forever. Failures are
//! therefore agreed ([`Ranks::agree`]) rather than returned by one rank alone.

use dpp_runtime::interpret::RunError;
use dpp_runtime::ErrorKind;

/// Why the ranks could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum DistError {
    /// MPI was initialised already in this process (only one [`Ranks`] per
    /// process can own it).
    #[error("MPI is already initialised in this process (one Ranks per process)")]
    AlreadyInitialised,
}

impl From<DistError> for RunError {
    fn from(error: DistError) -> RunError {
        RunError::internal(error.to_string())
    }
}

enum Comm {
    Single,
    #[cfg(feature = "mpi")]
    Mpi {
        // Declared before the universe: fields drop in order, and the
        // universe's drop finalises MPI.
        comm: mpi::topology::SimpleCommunicator,
        _universe: mpi::environment::Universe,
    },
}

/// This process among the ranks of a run.
pub struct Ranks {
    // Only MPI's variant has anything to read.
    #[cfg_attr(not(feature = "mpi"), allow(dead_code))]
    comm: Comm,
    rank: usize,
    size: usize,
}

// SAFETY: the only state that is not plainly Send and Sync is MPI's
// communicator handle. MPI is initialised with MPI_THREAD_SERIALIZED, which
// allows calls from any thread as long as no two run at once; dpp calls a
// `Ranks` only from the thread that drives a run (rayon's workers inside a
// stage never see it), and a run drives one stage or collective at a time.
// The handle itself is an opaque value that MPI allows to move between threads.
unsafe impl Send for Ranks {}
unsafe impl Sync for Ranks {}

/// Whether an MPI launcher (`mpirun`, `mpiexec`, `srun`) started this
/// process. Without one the process is a single rank and does not initialise
/// MPI at all: Open MPI's "singleton" start forks a daemon and sets up shared
/// memory, which costs time and fails where a process may not create files
/// (a file-size limit), for a run that needs none of it.
#[cfg(feature = "mpi")]
fn started_by_a_launcher() -> bool {
    // Open MPI, PMIx (Open MPI 4+, Slurm), and MPICH/Hydra's PMI.
    ["OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"]
        .iter()
        .any(|name| std::env::var_os(name).is_some())
}

impl std::fmt::Debug for Ranks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Ranks({} of {})", self.rank, self.size)
    }
}

/// Encodes an error kind as one byte for [`Ranks::agree`].
fn kind_code(kind: ErrorKind) -> u8 {
    match kind {
        ErrorKind::BadInput => 1,
        ErrorKind::ResourceLimit => 2,
        ErrorKind::Device => 3,
        ErrorKind::Internal => 4,
    }
}

fn kind_of(code: u8) -> ErrorKind {
    match code {
        1 => ErrorKind::BadInput,
        2 => ErrorKind::ResourceLimit,
        3 => ErrorKind::Device,
        _ => ErrorKind::Internal,
    }
}

/// FNV-1a, 64 bits: a hash every rank computes alike (std's hashers promise
/// no stability, and the ranks compare hashes, not Rust values).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |hash, byte| {
        (hash ^ u64::from(*byte)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

impl Ranks {
    /// Joins the run. With the `mpi` feature and a launcher (`mpirun`) this
    /// initialises MPI; a process started without one, or built without the
    /// feature, is a single rank of size 1 and never touches MPI. MPI is finalised when the `Ranks` is
    /// dropped, so keep it for the whole run; call its methods from one
    /// thread at a time (MPI is initialised for serialised calls).
    pub fn init() -> Result<Ranks, DistError> {
        #[cfg(feature = "mpi")]
        if started_by_a_launcher() {
            use mpi::traits::Communicator;
            let (universe, _) = mpi::initialize_with_threading(mpi::Threading::Serialized)
                .ok_or(DistError::AlreadyInitialised)?;
            // A communicator of our own, so that our messages never match a
            // receive of another library sharing the process's MPI.
            let comm = universe.world().duplicate();
            let (rank, size) = (comm.rank() as usize, comm.size() as usize);
            return Ok(Ranks {
                comm: Comm::Mpi {
                    comm,
                    _universe: universe,
                },
                rank,
                size,
            });
        }
        Ok(Ranks::single())
    }

    /// A single rank of size 1 that never touches MPI (for tests and for runs
    /// that are not distributed, even in a build with the `mpi` feature).
    pub fn single() -> Ranks {
        Ranks {
            comm: Comm::Single,
            rank: 0,
            size: 1,
        }
    }

    pub fn rank(&self) -> usize {
        self.rank
    }

    pub fn size(&self) -> usize {
        self.size
    }

    /// Whether this is rank 0, which gathers the image and writes outputs.
    pub fn is_root(&self) -> bool {
        self.rank == 0
    }

    #[cfg(feature = "mpi")]
    pub(crate) fn communicator(&self) -> Option<&mpi::topology::SimpleCommunicator> {
        match &self.comm {
            Comm::Single => None,
            Comm::Mpi { comm, .. } => Some(comm),
        }
    }

    /// Waits until every rank has called it.
    pub fn barrier(&self) {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::traits::CommunicatorCollectives;
            comm.barrier();
        }
    }

    /// Element-wise minimum over the ranks, in place on every rank.
    pub fn all_min_f32(&self, values: &mut [f32]) {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::collective::SystemOperation;
            use mpi::traits::CommunicatorCollectives;
            let mine = values.to_vec();
            comm.all_reduce_into(&mine[..], values, SystemOperation::min());
        }
        let _ = values;
    }

    /// Element-wise maximum over the ranks, in place on every rank.
    pub fn all_max_f32(&self, values: &mut [f32]) {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::collective::SystemOperation;
            use mpi::traits::CommunicatorCollectives;
            let mine = values.to_vec();
            comm.all_reduce_into(&mine[..], values, SystemOperation::max());
        }
        let _ = values;
    }

    /// The sum of `value` over the ranks, on every rank.
    pub fn all_sum_u64(&self, value: u64) -> u64 {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::collective::SystemOperation;
            use mpi::traits::CommunicatorCollectives;
            let mut sum = 0u64;
            comm.all_reduce_into(&value, &mut sum, SystemOperation::sum());
            return sum;
        }
        value
    }

    /// The sum of `value` over the ranks below this one (0 on rank 0): where
    /// this rank's part starts in a concatenation in rank order.
    pub fn exclusive_sum_u64(&self, value: u64) -> u64 {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::collective::SystemOperation;
            use mpi::traits::CommunicatorCollectives;
            let mut sum = 0u64;
            comm.exclusive_scan_into(&value, &mut sum, SystemOperation::sum());
            // MPI leaves rank 0's result undefined.
            return if self.rank == 0 { 0 } else { sum };
        }
        let _ = value;
        0
    }

    /// Every rank's bytes (of any length), in rank order, on every rank.
    pub fn all_gather_bytes(&self, mine: &[u8]) -> Vec<Vec<u8>> {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::datatype::PartitionMut;
            use mpi::traits::CommunicatorCollectives;
            let count = mpi::Count::try_from(mine.len()).expect("a gathered message under 2 GiB");
            let mut counts = vec![0 as mpi::Count; self.size];
            comm.all_gather_into(&count, &mut counts[..]);
            let displs: Vec<mpi::Count> = counts
                .iter()
                .scan(0 as mpi::Count, |at, c| {
                    let start = *at;
                    *at += c;
                    Some(start)
                })
                .collect();
            let total: usize = counts.iter().map(|c| *c as usize).sum();
            if total == 0 {
                // Every rank knows; and two empty Vecs share one dangling
                // pointer, which Open MPI rejects as aliased buffers.
                return vec![Vec::new(); self.size];
            }
            let mut all = vec![0u8; total];
            {
                let mut partition = PartitionMut::new(&mut all[..], &counts[..], &displs[..]);
                comm.all_gather_varcount_into(mine, &mut partition);
            }
            return counts
                .iter()
                .zip(&displs)
                .map(|(c, d)| all[*d as usize..(*d + *c) as usize].to_vec())
                .collect();
        }
        vec![mine.to_vec()]
    }

    /// Rank `root`'s bytes into `bytes` on every rank (resized to fit).
    pub fn broadcast_bytes(&self, root: usize, bytes: &mut Vec<u8>) {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::traits::{Communicator, Root};
            let process = comm.process_at_rank(root as mpi::Rank);
            let mut len = bytes.len() as u64;
            process.broadcast_into(&mut len);
            bytes.resize(len as usize, 0);
            process.broadcast_into(&mut bytes[..]);
        }
        let _ = (root, bytes);
    }

    /// A check-point where the ranks agree on failure: every rank says
    /// whether `mine` failed, and if any did, every rank returns an error —
    /// a failing rank its own, the others one of the failing kind whose
    /// message is `rank R: <message>` of the lowest failing rank R. So a
    /// rank that cannot read its piece ends the run on every rank instead
    /// of leaving them waiting in the next collective.
    pub fn agree<T>(&self, mine: Result<T, RunError>) -> Result<T, RunError> {
        if self.size == 1 {
            return mine;
        }
        let status = match &mine {
            Ok(_) => vec![0],
            Err(error) => {
                let mut bytes = vec![kind_code(error.kind)];
                bytes.extend_from_slice(error.message.as_bytes());
                bytes
            }
        };
        let all = self.all_gather_bytes(&status);
        match mine {
            Err(error) => Err(error),
            Ok(value) => match all.iter().enumerate().find(|(_, s)| s[0] != 0) {
                None => Ok(value),
                Some((rank, status)) => Err(RunError::new(
                    kind_of(status[0]),
                    format!("rank {rank}: {}", String::from_utf8_lossy(&status[1..])),
                )),
            },
        }
    }

    /// Checks that every rank passed the same `bytes` (its command line, a
    /// pipeline's text, a schedule): a BadInput error on every rank, naming
    /// the first rank that differs from rank 0, if not. Compares 64-bit
    /// hashes, so one collective of 8 bytes per rank.
    pub fn same_on_every_rank(&self, what: &str, bytes: &[u8]) -> Result<(), RunError> {
        let hashes = self.all_gather_bytes(&fnv1a(bytes).to_le_bytes());
        match hashes.iter().position(|h| h != &hashes[0]) {
            None => Ok(()),
            Some(rank) => Err(RunError::bad_input(format!(
                "{what} differs between ranks: rank {rank}'s is not rank 0's"
            ))),
        }
    }

    /// Ends the whole run — **every rank**, not just this one (MPI_Abort on
    /// the run's communicator; `mpirun` then exits with `code`). For a
    /// failure in the middle of a collective, where returning would leave
    /// the other ranks waiting forever. Prefer [`Ranks::agree`] wherever
    /// the ranks can still meet.
    pub fn abort(&self, code: i32) -> ! {
        #[cfg(feature = "mpi")]
        if let Some(comm) = self.communicator() {
            use mpi::traits::Communicator;
            comm.abort(code);
        }
        std::process::exit(code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_single_rank_is_its_own_collective() {
        let ranks = Ranks::single();
        assert_eq!((ranks.rank(), ranks.size(), ranks.is_root()), (0, 1, true));
        ranks.barrier();
        let mut values = [1.0, -2.0];
        ranks.all_min_f32(&mut values);
        ranks.all_max_f32(&mut values);
        assert_eq!(values, [1.0, -2.0]);
        assert_eq!(ranks.all_sum_u64(7), 7);
        assert_eq!(ranks.exclusive_sum_u64(7), 0);
        assert_eq!(ranks.all_gather_bytes(b"abc"), vec![b"abc".to_vec()]);
        let mut bytes = b"x".to_vec();
        ranks.broadcast_bytes(0, &mut bytes);
        assert_eq!(bytes, b"x");
        assert_eq!(ranks.agree(Ok::<_, RunError>(3)), Ok(3));
        let failed: Result<(), _> = ranks.agree(Err(RunError::bad_input("no piece")));
        assert_eq!(failed, Err(RunError::bad_input("no piece")));
        assert_eq!(ranks.same_on_every_rank("command line", b"dpp run"), Ok(()));
    }

    #[test]
    fn kinds_survive_their_codes() {
        for kind in [
            ErrorKind::BadInput,
            ErrorKind::ResourceLimit,
            ErrorKind::Device,
            ErrorKind::Internal,
        ] {
            assert_eq!(kind_of(kind_code(kind)), kind);
        }
        assert_ne!(fnv1a(b"a"), fnv1a(b"b"));
    }
}

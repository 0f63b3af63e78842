//! How a rank gets the values of other ranks' rows that it reads (docs/cluster.md, "What
//! spreads"): a vector in the unknowns' order is exact in the rank's own rows (a solve's w,
//! a right side's b_n), and an [`Exchange`] brings it the values it reads elsewhere from
//! the ranks that hold their rows, in one `MPI_Alltoallv`: at every solve, what it reads
//! (its rows' neighbours, Γ3's unknowns, a follower's history's reach: the halo), not the
//! whole vector, 8 bytes an unknown to every rank.

use super::{check, Layout, Result};
use crate::Error;
use std::ffi::{c_int, c_void};

extern "C" {
    fn vc_alltoall_counts(send: *const c_int, recv: *mut c_int) -> c_int;
    fn vc_alltoallv(
        send: *const c_void,
        scounts: *const c_int,
        sdispls: *const c_int,
        recv: *mut c_void,
        rcounts: *const c_int,
        rdispls: *const c_int,
        ints: c_int,
    ) -> c_int;
}

/// Which unknowns a rank sends to each rank and which it receives from each, and each
/// rank's count and first place among them: made once, collectively, of the unknowns each
/// rank reads ([`Exchange::new`]).
pub struct Exchange {
    send: Vec<u32>,
    send_counts: Vec<c_int>,
    send_displs: Vec<c_int>,
    recv: Vec<u32>,
    recv_counts: Vec<c_int>,
    recv_displs: Vec<c_int>,
}

impl Exchange {
    /// The exchange by which this rank receives the unknowns `reads` (none of its own rows,
    /// each once) from the ranks that hold their rows; every rank calls it at once with
    /// what it reads. The ranks tell each owner which of its unknowns they read: one count
    /// and one list from each rank to each.
    pub fn new(layout: &Layout, mut reads: Vec<u32>) -> Result<Exchange> {
        let size = layout.blocks.len() - 1;
        let owner = |i: u32| layout.rank_of_row(layout.row(i as usize));
        reads.sort_by_key(|&i| (owner(i), i));
        let mut recv_counts = vec![0; size];
        reads.iter().for_each(|&i| recv_counts[owner(i)] += 1);
        // What the others read of this rank's rows: the values it sends them at each run.
        let (send, send_counts) = all_to_all(&reads, &recv_counts)?;
        let (send_displs, recv_displs) = (displacements(&send_counts), displacements(&recv_counts));
        Ok(Exchange {
            send,
            send_counts,
            send_displs,
            recv: reads,
            recv_counts,
            recv_displs,
        })
    }

    /// The exchange of vectors that hold each unknown at `place(unknown)`, not at its own
    /// index (a follower's, held at some unknowns alone: `Reads::held`).
    pub fn place(&mut self, place: impl Fn(u32) -> u32) {
        (self.send.iter_mut().chain(&mut self.recv)).for_each(|i| *i = place(*i));
    }

    /// v at the unknowns this rank reads ← their values on the ranks that hold their rows,
    /// where v is exact in its own rows (collective).
    pub fn run(&self, v: &mut [f64]) -> Result<()> {
        let sent: Vec<f64> = self.send.iter().map(|&i| v[i as usize]).collect();
        let mut received = vec![0.0; self.recv.len()];
        // SAFETY: as in `all_to_all`, of doubles; MPI writes `received` within the call.
        let code = unsafe {
            vc_alltoallv(
                sent.as_ptr().cast(),
                self.send_counts.as_ptr(),
                self.send_displs.as_ptr(),
                received.as_mut_ptr().cast(),
                self.recv_counts.as_ptr(),
                self.recv_displs.as_ptr(),
                0,
            )
        };
        check(code, "MPI_Alltoallv")?;
        (self.recv.iter())
            .zip(received)
            .for_each(|(&i, x)| v[i as usize] = x);
        Ok(())
    }
}

/// Each rank's part of `parts` (given on rank 0, one a rank; None on the others), sent from
/// rank 0 (collective): one count and one list from rank 0 to each. A part must hold
/// fewer than 2^31 values (MPI's counts): the caller refuses larger ones before, on every
/// rank, since rank 0 failing here alone would leave the others in the call.
pub fn scatter_from_first(parts: Option<&[Vec<u32>]>) -> Result<Vec<u32>> {
    let size = super::world()?.1;
    let too_many = |_| Error::solve("a rank's part of the mesh exceeds MPI's counts".to_string());
    let mut send_counts = vec![0; size];
    for (count, part) in send_counts.iter_mut().zip(parts.unwrap_or_default()) {
        *count = c_int::try_from(part.len()).map_err(too_many)?;
    }
    let send: Vec<u32> = parts.unwrap_or_default().concat();
    Ok(all_to_all(&send, &send_counts)?.0)
}

/// `values` cut by `counts` (in rank order), each rank's piece sent to it, and what each
/// rank sends this one, with their counts (collective: one count and one list from each
/// rank to each; the values cross as ints).
fn all_to_all(values: &[u32], counts: &[c_int]) -> Result<(Vec<u32>, Vec<c_int>)> {
    let mut received_counts = vec![0; counts.len()];
    // SAFETY: both arrays hold one count for each rank; MPI writes received_counts.
    let code = unsafe { vc_alltoall_counts(counts.as_ptr(), received_counts.as_mut_ptr()) };
    check(code, "MPI_Alltoall")?;
    let (displs, received_displs) = (displacements(counts), displacements(&received_counts));
    let mut received = vec![0u32; received_counts.iter().map(|&c| c as usize).sum()];
    // SAFETY: the counts and displacements cut `values` and `received` as each holds them,
    // in rank order; MPI writes `received` within the call.
    let code = unsafe {
        vc_alltoallv(
            values.as_ptr().cast(),
            counts.as_ptr(),
            displs.as_ptr(),
            received.as_mut_ptr().cast(),
            received_counts.as_ptr(),
            received_displs.as_ptr(),
            1,
        )
    };
    check(code, "MPI_Alltoallv")?;
    Ok((received, received_counts))
}

/// Each rank's first place in an array cut by `counts`, in rank order.
pub(super) fn displacements(counts: &[c_int]) -> Vec<c_int> {
    (counts.iter())
        .scan(0, |at, &c| Some(std::mem::replace(at, *at + c)))
        .collect()
}

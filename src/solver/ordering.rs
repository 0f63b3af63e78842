//! The fill-reducing ordering of K_A with the constrained dofs C (the Γ3 rows' dofs) last.
//!
//! The step solver needs C last (`dual/`: G = L_CC⁻¹ E), so the ordering is one of the
//! other dofs followed by C. It is METIS's nested dissection (`METIS_NodeND`) of the graph
//! of the other dofs' nodes: dofs of one node have the same sparsity (consecutive columns
//! with equal patterns, found here from the matrix alone), so the graph has one vertex per
//! node — d times fewer vertices and d² times fewer edges than the dof graph — and each
//! vertex expands to its dofs in order.
//!
//! Why not AMD, as faer offers: ordering the whole matrix by AMD and then moving C to the end
//! adds 41–43% fill in 3D, and nested dissection with C left out of the graph cuts nnz(L) by
//! 29–35% against that (measured on the block meshes; see docs/performance.md).
//! METIS is deterministic (fixed seed; calls are serialized, see `dissect`), so a resumed run
//! orders and factors K_A exactly as the uninterrupted run did.

use crate::fem::Sparse;
use crate::{Error, Result};

/// `fwd[new] = old`: the interior dofs in nested-dissection order, then the dofs of `last`
/// in the nested-dissection order of the graph they induce.
pub fn constrained_last(a: &Sparse, last: &[usize]) -> Result<Vec<usize>> {
    let n = a.nrows();
    let (col_ptr, row_idx) = (a.symbolic().col_ptr(), a.symbolic().row_idx());
    let pattern = |j: usize| &row_idx[col_ptr[j]..col_ptr[j + 1]];
    let mut in_last = vec![false; n];
    for &d in last {
        in_last[d] = true;
    }
    // Supervariables: runs of consecutive columns with the same pattern (a node's dofs).
    let mut first = Vec::new(); // first column of each supervariable
    for j in 0..n {
        if j == 0 || pattern(j) != pattern(j - 1) {
            first.push(j);
        }
    }
    first.push(n);
    let mut group = vec![0; n];
    for (g, w) in first.windows(2).enumerate() {
        group[w[0]..w[1]].fill(g);
    }
    // The interior dofs of the supervariables in nested-dissection order, then C likewise.
    let groups = first.len() - 1;
    let mut order = Vec::with_capacity(n);
    let in_last = &in_last;
    let first = &first;
    for side in [false, true] {
        let dofs = move |g: usize| (first[g]..first[g + 1]).filter(move |&j| in_last[j] == side);
        let members: Vec<usize> = (0..groups).filter(|&g| dofs(g).next().is_some()).collect();
        for g in dissect(&members, &group, &pattern, first)? {
            order.extend(dofs(g));
        }
    }
    debug_assert_eq!(order.len(), n);
    Ok(order)
}

/// The supervariables `members` (sorted) in METIS's nested-dissection order of the graph
/// they induce (two are adjacent when K_A couples their dofs).
fn dissect<'a>(
    members: &[usize],
    group: &[usize],
    pattern: &impl Fn(usize) -> &'a [usize],
    first: &[usize],
) -> Result<Vec<usize>> {
    let idx = |v: usize| {
        metis_sys::idx_t::try_from(v)
            .map_err(|_| Error::solve(format!("K_A is too large for METIS ({v} entries)")))
    };
    let vertex = |g: usize| members.binary_search(&g).ok();
    let mut xadj = vec![0];
    let mut adjncy = Vec::new();
    for &g in members {
        let mut previous = usize::MAX;
        for &r in pattern(first[g]) {
            let h = group[r];
            if h != g && h != previous {
                if let Some(v) = vertex(h) {
                    adjncy.push(idx(v)?);
                }
            }
            previous = h;
        }
        xadj.push(idx(adjncy.len())?);
    }
    let nv = members.len();
    if nv == 0 {
        return Ok(Vec::new());
    }
    let mut nvtxs = idx(nv)?;
    let (mut perm, mut iperm) = (vec![0; nv], vec![0; nv]);
    // METIS seeds and draws from one random generator shared by the whole process (GKlib's,
    // not thread-safe): two orderings at once (threads of a study, tests run in parallel)
    // raced on it and came out different from run to run. One call at a time, each seeded
    // afresh by METIS, gives every run the same ordering.
    static METIS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one_at_a_time = METIS.lock().unwrap_or_else(|e| e.into_inner());
    // SAFETY: xadj (nv + 1 entries) and adjncy describe a graph on nv vertices with no self
    // loops, symmetric because the pattern of K_A is; perm and iperm hold nv entries; null
    // weights and options mean unit weights and METIS's defaults. METIS only reads the graph
    // and writes perm and iperm.
    let status = unsafe {
        metis_sys::METIS_NodeND(
            &mut nvtxs,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return Err(Error::solve(format!(
            "METIS could not order K_A (status {status})"
        )));
    }
    // METIS's `perm` lists the vertices in their new order.
    Ok(perm.iter().map(|&v| members[v as usize]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::linalg::cholesky::{
        factorize_symbolic_cholesky, CholeskySymbolicParams, SymmetricOrdering,
    };
    use faer::sparse::{SparseColMat, Triplet};
    use faer::Side;

    /// A matrix with the structure of 3D P1 elasticity on a side³ grid of nodes: 3 dofs per
    /// node, every node coupled with its 26 neighbours by a full 3×3 block, diagonally
    /// dominant; C = the dofs of the nodes on the face z = 0.
    fn grid(side: usize) -> (Sparse, Vec<usize>) {
        let node = |x: usize, y: usize, z: usize| (z * side + y) * side + x;
        let mut t = Vec::new();
        let mut diag = vec![1.0; 3 * side * side * side];
        for (x, y, z) in
            (0..side).flat_map(|z| (0..side).flat_map(move |y| (0..side).map(move |x| (x, y, z))))
        {
            for (dx, dy, dz) in (-1i64..=1)
                .flat_map(|a| (-1i64..=1).flat_map(move |b| (-1i64..=1).map(move |c| (a, b, c))))
            {
                let (x2, y2, z2) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                let inside = |v: i64| (0..side as i64).contains(&v);
                if (dx, dy, dz) == (0, 0, 0) || !(inside(x2) && inside(y2) && inside(z2)) {
                    continue;
                }
                let (p, q) = (node(x, y, z), node(x2 as usize, y2 as usize, z2 as usize));
                for a in 0..3 {
                    for b in 0..3 {
                        let v = -0.1 - 0.01 * ((a + 2 * b + p + q) % 5) as f64;
                        t.push(Triplet::new(3 * p + a, 3 * q + b, v));
                        diag[3 * p + a] -= v;
                    }
                }
            }
        }
        t.extend(diag.iter().enumerate().map(|(i, &v)| Triplet::new(i, i, v)));
        let n = diag.len();
        let last = (0..side * side).flat_map(|p| 3 * p..3 * p + 3).collect();
        (SparseColMat::try_new_from_triplets(n, n, &t).unwrap(), last)
    }

    /// Stored values of the Cholesky factor of `a` in the order `fwd`.
    fn fill(a: &Sparse, fwd: &[usize]) -> usize {
        let mut inv = vec![0; fwd.len()];
        for (i, &d) in fwd.iter().enumerate() {
            inv[d] = i;
        }
        let perm = faer::perm::PermRef::new_checked(fwd, &inv, fwd.len());
        factorize_symbolic_cholesky(
            a.symbolic(),
            Side::Lower,
            SymmetricOrdering::Custom(perm),
            CholeskySymbolicParams::default(),
        )
        .unwrap()
        .len_val()
    }

    /// A permutation with C last, the same on every call, and with less
    /// fill than AMD of the whole matrix with C then moved last (what it replaced).
    #[test]
    fn nested_dissection_with_c_last_fills_less_than_amd_moved() {
        let (a, last) = grid(14);
        let n = a.nrows();
        let fwd = constrained_last(&a, &last).unwrap();
        let mut seen = vec![false; n];
        for &d in &fwd {
            assert!(!seen[d], "dof {d} twice");
            seen[d] = true;
        }
        assert_eq!(fwd.len(), n);
        let mut tail = fwd[n - last.len()..].to_vec();
        tail.sort_unstable();
        assert_eq!(tail, last);
        assert_eq!(fwd, constrained_last(&a, &last).unwrap(), "deterministic");
        // Also when orderings run at once (METIS's random generator is process-wide).
        std::thread::scope(|scope| {
            let runs: Vec<_> = (0..4)
                .map(|_| scope.spawn(|| constrained_last(&a, &last).unwrap()))
                .collect();
            for run in runs {
                assert_eq!(run.join().unwrap(), fwd, "concurrent orderings differ");
            }
        });

        let amd = factorize_symbolic_cholesky(
            a.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .unwrap();
        let order = amd.perm().unwrap().arrays().0.to_vec();
        let is_last = |d: &usize| last.contains(d);
        let mut moved: Vec<usize> = order.iter().copied().filter(|d| !is_last(d)).collect();
        moved.extend(order.iter().copied().filter(is_last));
        let (nd, amd) = (fill(&a, &fwd), fill(&a, &moved));
        assert!(nd < amd * 9 / 10, "nested dissection {nd}, AMD moved {amd}");
    }
}

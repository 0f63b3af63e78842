//! The Dirichlet conditions and the dof numbering they give: the clamped groups of
//! `mesh.groups.fixed` (u = 0, every component) and the `[[dirichlet]]` entries (chosen
//! components, or the normal one on a flat group, equal to g(x, t)).
//!
//! # Numbering
//!
//! Global dof d·node + c. A dof with no condition is *free*: the free dofs are numbered
//! 0..n_free in global order, the unknowns of the step problem. A dof held at zero for all
//! t is eliminated (no index), as the clamped Γ1 always was: u = w = 0 there. A dof with a
//! prescribed value that is not identically zero is *prescribed*: numbered n_free..n_dofs
//! after the free ones, in global order, so the vectors the loop keeps (u, w, m, b) have
//! n_dofs entries and the step problem reads their first n_free. Without prescribed values
//! n_dofs = n_free and every vector, matrix and result is what it was without them.
//!
//! # Prescribed displacements in the scheme
//!
//! The scheme's unknown is the velocity: u_{n+1} = u_n + k w_n. A condition u(x, t) = g(x, t)
//! at a prescribed dof i is imposed on the step's result, u_{n+1,i} = g_i(t_{n+1}), which
//! fixes the velocity there before the step is solved:
//!
//!   w_{n,i} = (g_i(t_{n+1}) − u_{n,i}) / k,
//!
//! exactly (u_{n,i} is the value the previous step reached, so round-off does not drift).
//! Splitting the step matrix M (K_A, or K_A + k K_B + k² r(0) K_R for the implicit variant)
//! into free (f) and prescribed (p) blocks, the step problem on the free dofs is the same
//! variational inequality with
//!
//!   M_ff w_f = b_f − M_fp w_p,    b = f_n − K_B u_n − K_R m_n − g_F  (all n_dofs rows),
//!
//! where u_n and m_n include the prescribed dofs, so that K_B u_n and K_R m_n see the
//! prescribed displacement and its memory. M_ff is what is factored: symmetric positive
//! definite once the conditions remove the rigid motions, of the cost it had.
//!
//! # Inclined planes: nodal frames
//!
//! `normal` on a flat group holds u·n, n the plane's unit outward normal. Where n is a
//! coordinate axis that is one dof (the component, with the sign of n). Where it is not,
//! each node of the group gets a frame of its own ([`Frames`]): orthonormal axes a_0, a_1
//! (, a_2), the first ones the directions held there (n, and where another condition meets
//! the plane its direction), and the node's dofs are the components ũ_k = u·a_k, so that
//! u·n = 0 is again one dof held at zero and eliminated. With Q the block-diagonal rotation (the identity at
//! every other node), u = Q ũ, and the discrete problem in ũ is the same one written in
//! other coordinates: K̃ = Qᵀ K Q for each matrix (the element entries rotated where a
//! vertex has a frame: `Cell::parts_in`), f̃ = Qᵀ f for the loads and g_F (`Frames::spread`),
//! the constraint rows P̃ = P Q (a row's direction in the node's frame), and the results u =
//! Q ũ (`Frames::to_space`). Q is orthogonal, so K̃ stays symmetric positive definite with
//! the same sparsity pattern and the same cost; the rows of one node keep their angles, so
//! the contact and friction solvers see the same geometry. Nodes without a frame take no
//! extra operation: a scene without an inclined plane keeps its bits.
//!
//! # Rules
//!
//! A dof held by two conditions is allowed when both hold it at zero (a clamped edge shared
//! with a symmetry plane) or prescribe the same value as written (the same expression, and
//! for `normal` the same sign); otherwise it is refused, naming both. `normal` needs a flat
//! group (a curved or kinked one is refused). At a node that two conditions hold in
//! different directions (two planes meeting, or a plane and an axis component) with one of
//! them inclined, the directions must be perpendicular (the frame's first axes) or parallel
//! (the same dof); an oblique pair is refused. A clamped node keeps no frame. A body (each
//! connected part) must have its rigid motions removed by the conditions, or `check` and
//! `run` refuse it.

use super::{group, Sparse};
use crate::mesh::{Group, Mesh, Part};
use crate::scene::{Components, Scene};
use crate::{Error, Result};
use std::collections::{BTreeMap, HashMap};

/// A prescribed dof: global dof d·node + c gets index `dof` (≥ n_free) and the value
/// scale · value_`value`(x, t) of `[[dirichlet]]` entry `entry`.
#[derive(Clone, Copy, Debug)]
pub struct Prescribed {
    pub dof: usize,
    pub node: usize,
    pub entry: usize,
    pub value: usize,
    pub scale: f64,
}

/// A global dof's index in the numbering: a free dof's 0..n_free, a prescribed one's
/// n_free..n_dofs, or none where the dof is held at zero (`DofIndices::whole`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct DofIndex(u32);

impl DofIndex {
    /// A dof held at zero.
    const HELD: DofIndex = DofIndex(u32::MAX);

    fn get(self) -> Option<usize> {
        (self != DofIndex::HELD).then_some(self.0 as usize)
    }
}

/// Global dof d·node + c → its index in the numbering (`Numbering::free`), and back.
///
/// The held dofs are a boundary's, few beside the whole, and they say every index: a free
/// dof g is the (g − h)-th unknown, h the held dofs before it, and a prescribed one comes
/// n_free + its place among the prescribed. So the numbering keeps those two lists and
/// finds an index by binary search in them; the index of every dof of the whole (four
/// bytes a dof) it keeps only where it reads every cell ([`DofIndices::whole`]: one
/// process and rank 0 of several, whose assembly looks one up at every entry of every
/// cell, until it lets go of the cells: [`DofIndices::forget_whole`]). A follower rank of
/// several then holds nothing of the whole problem here.
#[derive(Clone, Debug, Default)]
pub struct DofIndices {
    /// The global dofs: d × the nodes.
    n: usize,
    n_free: usize,
    /// The held global dofs (at zero or prescribed), increasing.
    held: Vec<u32>,
    /// The prescribed global dofs, increasing: their indices are n_free, n_free + 1, …
    prescribed: Vec<u32>,
    /// Each global dof's index, where kept; else empty.
    whole: Vec<DofIndex>,
}

impl DofIndices {
    /// The most dofs a numbering holds.
    pub const MAX_DOFS: usize = u32::MAX as usize;

    /// A numbering of n global dofs in which each is its own index (no condition held).
    pub fn each(n: usize) -> DofIndices {
        DofIndices {
            n,
            n_free: n,
            ..DofIndices::default()
        }
    }

    /// The numbering of n global dofs of which `held` (increasing) are held and
    /// `prescribed` (increasing, among them) prescribed; the rest free, in global order.
    fn new(n: usize, held: Vec<u32>, prescribed: Vec<u32>) -> DofIndices {
        DofIndices {
            n,
            n_free: n - held.len(),
            held,
            prescribed,
            whole: Vec::new(),
        }
    }

    /// The same numbering with the index of every dof kept, so that [`DofIndices::get`]
    /// reads one array instead of searching.
    pub fn whole(mut self) -> DofIndices {
        self.whole = (0..self.n)
            .map(|g| {
                self.search(g)
                    .map_or(DofIndex::HELD, |i| DofIndex(i as u32))
            })
            .collect();
        self
    }

    /// The same numbering without the index of every dof ([`DofIndices::whole`]), which
    /// [`DofIndices::get`] then finds by searching: where the rank no longer reads every
    /// cell.
    pub fn forget_whole(&mut self) {
        self.whole = Vec::new();
    }

    /// The global dofs: d × the nodes.
    pub fn dofs(&self) -> usize {
        self.n
    }

    /// The index of global dof g; none where g is held at zero.
    #[inline]
    pub fn get(&self, g: usize) -> Option<usize> {
        match self.whole.get(g) {
            Some(i) => i.get(),
            None => self.search(g),
        }
    }

    fn search(&self, g: usize) -> Option<usize> {
        match self.held.binary_search(&(g as u32)) {
            Err(h) => Some(g - h),
            Ok(_) => (self.prescribed.binary_search(&(g as u32)).ok()).map(|p| self.n_free + p),
        }
    }

    /// The unknown of global dof g (its index among the n_free), where it is one: neither
    /// held at zero nor prescribed.
    pub fn unknown(&self, g: usize) -> Option<usize> {
        self.get(g).filter(|&i| i < self.n_free)
    }

    /// Whether a condition holds global dof g (at zero or at a prescribed value).
    pub fn is_held(&self, g: usize) -> bool {
        self.held.binary_search(&(g as u32)).is_ok()
    }

    /// The global dof of index i (i < n_dofs).
    pub fn global(&self, i: usize) -> usize {
        if i >= self.n_free {
            return self.prescribed[i - self.n_free] as usize;
        }
        // The i-th free dof lies after the held ones with fewer than i + 1 free dofs before
        // them: held[t] − t of those is at most i, and it does not decrease with t.
        let (mut lo, mut hi) = (0, self.held.len());
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.held[mid] as usize - mid <= i {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        i + lo
    }

    /// The indices of node p's d dofs, those held at zero left out.
    pub fn of_node(&self, d: usize, p: usize) -> impl Iterator<Item = usize> + '_ {
        (d * p..d * (p + 1)).filter_map(|g| self.get(g))
    }

    /// Each global dof's index in global order (−1 where held at zero).
    pub fn signed(&self) -> impl Iterator<Item = i64> + '_ {
        (0..self.n).map(|g| self.get(g).map_or(-1, |i| i as i64))
    }
}

/// The dof numbering under the scene's conditions.
pub struct Numbering {
    /// Global dof → index: free dofs 0..n_free, prescribed n_free..n_dofs, none if held at 0.
    pub free: DofIndices,
    pub n_free: usize,
    pub n_dofs: usize,
    pub prescribed: Vec<Prescribed>,
    /// Every held global dof (at zero or prescribed), increasing, with the condition that
    /// holds it: the first to name it, the clamped groups in order, then the `[[dirichlet]]`
    /// entries (the reactions of `fem::reactions` are reported per condition group).
    pub held_by: Vec<(usize, Source)>,
    /// The frames of the nodes an inclined `normal` condition holds: there global dof
    /// d·node + k is the component along the frame's axis k.
    pub frames: Frames,
}

/// What holds a dof while the numbering is built: the source (fixed group i, or
/// `[[dirichlet]]` entry i) and the value (None: zero).
#[derive(Clone, Copy)]
struct Hold {
    source: Source,
    value: Option<(usize, f64)>,
}

/// A Dirichlet condition of the scene: clamped group `mesh.groups.fixed[i]` or
/// `[[dirichlet]]` entry i.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    Fixed(usize),
    Dirichlet(usize),
}

impl Hold {
    /// Both hold at zero, or both prescribe the same written value with the same sign.
    fn agrees(self, other: Hold, scene: &Scene) -> bool {
        let written = |h: Hold| match (h.source, h.value) {
            (Source::Dirichlet(e), Some((v, scale))) => {
                Some((&scene.physics.dirichlet[e].written[v], scale))
            }
            _ => None,
        };
        written(self) == written(other)
    }
}

impl Source {
    /// The group it holds, as the scene names it.
    pub fn group(self, scene: &Scene) -> &str {
        match self {
            Source::Fixed(i) => &scene.mesh.groups.fixed[i],
            Source::Dirichlet(i) => &scene.physics.dirichlet[i].on,
        }
    }

    fn describe(self, scene: &Scene) -> String {
        match self {
            Source::Fixed(i) => format!(
                "the clamped group '{}' (mesh.groups.fixed)",
                scene.mesh.groups.fixed[i]
            ),
            Source::Dirichlet(i) => format!("'{}' (dirichlet[{i}])", scene.physics.dirichlet[i].on),
        }
    }
}

impl Numbering {
    /// The numbering of `scene`'s conditions on `mesh`, every rule checked; those of the
    /// body's parts (`Numbering::check_parts`, which read every cell) where `parts`: a
    /// follower rank of several, whose mesh has no cells yet, leaves them to rank 0, and
    /// keeps no index of every dof ([`DofIndices::whole`]).
    pub fn new(mesh: &Mesh, scene: &Scene, parts: bool) -> Result<Numbering> {
        let d = mesh.dim;
        if d * mesh.nodes.len() >= DofIndices::MAX_DOFS {
            return Err(Error::input(format!(
                "{}: {} nodes make {} dofs, more than the {} that viscontact numbers: \
                 split the body, or mesh it coarser",
                mesh.path.display(),
                mesh.nodes.len(),
                d * mesh.nodes.len(),
                DofIndices::MAX_DOFS - 1
            )));
        }
        // The held dofs alone (a boundary's), not a slot of every dof: 40 bytes a dof of the
        // whole on every rank, the largest thing a follower's setup held of it.
        let mut holds: BTreeMap<usize, Hold> = BTreeMap::new();
        // The clamped nodes, increasing: a boundary's, not a flag of every node.
        let mut clamped = Vec::new();
        for (i, name) in scene.mesh.groups.fixed.iter().enumerate() {
            let g = group(mesh, scene, "mesh.groups.fixed", name)?;
            for node in mesh.group_nodes(g) {
                clamped.push(node);
                for c in 0..d {
                    let hold = Hold {
                        source: Source::Fixed(i),
                        value: None,
                    };
                    put(&mut holds, d * node + c, hold, mesh, scene)?;
                }
            }
        }
        let mut entries = Vec::new();
        for (i, e) in scene.physics.dirichlet.iter().enumerate() {
            let g = group(mesh, scene, &format!("dirichlet[{i}].on"), &e.on)?;
            entries.push((mesh.group_nodes(g), directions(mesh, scene, g, i)?));
        }
        clamped.sort_unstable();
        clamped.dedup();
        let frames = Frames::new(mesh, scene, &entries, &clamped)?;
        for (i, (nodes, held)) in entries.iter().enumerate() {
            let e = &scene.physics.dirichlet[i];
            for h in held {
                for &node in nodes {
                    let (c, sign) = frames.component(node, h.dir, d);
                    let hold = Hold {
                        source: Source::Dirichlet(i),
                        value: (!e.is_zero(h.value)).then_some((h.value, sign)),
                    };
                    put(&mut holds, d * node + c, hold, mesh, scene)?;
                }
            }
        }
        let mut numbering = Numbering::of((&holds, d * mesh.nodes.len()), d, frames);
        numbering.check(mesh, scene)?;
        if parts {
            numbering.free = numbering.free.whole();
            numbering.check_parts(mesh, scene)?;
        }
        Ok(numbering)
    }

    /// Free dofs first, then prescribed ones, each in global order: of `n` dofs, those
    /// `holds` names held.
    fn of((holds, n): (&BTreeMap<usize, Hold>, usize), d: usize, frames: Frames) -> Numbering {
        let held = holds.keys().map(|&g| g as u32).collect();
        let held_by = holds.iter().map(|(&g, h)| (g, h.source)).collect();
        let n_free = n - holds.len();
        let mut prescribed = Vec::new();
        let mut prescribed_dofs = Vec::new();
        for (&g, h) in holds {
            if let Hold {
                source: Source::Dirichlet(entry),
                value: Some((value, scale)),
            } = *h
            {
                prescribed.push(Prescribed {
                    dof: n_free + prescribed.len(),
                    node: g / d,
                    entry,
                    value,
                    scale,
                });
                prescribed_dofs.push(g as u32);
            }
        }
        Numbering {
            free: DofIndices::new(n, held, prescribed_dofs),
            n_free,
            n_dofs: n_free + prescribed.len(),
            prescribed,
            held_by,
            frames,
        }
    }

    /// Something free, and some condition.
    fn check(&self, mesh: &Mesh, scene: &Scene) -> Result<()> {
        let file = scene.path.display();
        if self.n_free == 0 {
            return Err(Error::input(format!(
                "{file}: every dof of '{}' carries a condition ({}); nothing is left to \
                 solve for",
                mesh.path.display(),
                conditions(scene)
            )));
        }
        if scene.mesh.groups.fixed.is_empty() && scene.physics.dirichlet.is_empty() {
            return Err(Error::input(format!(
                "{file}: key 'mesh.groups.fixed': the scene has no condition \
                 (mesh.groups.fixed = [] and no [[dirichlet]]), so the body is free to move \
                 as a rigid body and K_A is singular; name a clamped group, or add \
                 [[dirichlet]] entries that hold every rigid motion"
            )));
        }
        Ok(())
    }

    /// Every part of the body (its cells connected by their nodes) held against its rigid
    /// motions.
    fn check_parts(&self, mesh: &Mesh, scene: &Scene) -> Result<()> {
        let file = scene.path.display();
        let d = mesh.dim;
        let held: Vec<bool> = (0..mesh.nodes.len())
            .map(|p| (d * p..d * (p + 1)).any(|g| self.free.is_held(g)))
            .collect();
        mesh.check_parts(&held, &conditions(scene), scene.mesh.separate_parts)
            .map_err(|e| Error::input(format!("{file}: {e}")))?;
        if scene.physics.dirichlet.is_empty() {
            // Clamped groups hold whole facets: every part that touches one is held.
            return Ok(());
        }
        for (k, part) in mesh.parts().iter().enumerate() {
            if let Some(motion) = self.rigid_motion_left(mesh, part) {
                return Err(Error::input(format!(
                    "{file}: the conditions ({}) leave {} free to move as a rigid body ({motion}), \
                     so K_A is singular; clamp a group in mesh.groups.fixed or add [[dirichlet]] \
                     entries that hold that motion (a roller on a plane normal to the motion's \
                     direction, or a second symmetry plane)",
                    conditions(scene),
                    match mesh.parts().len() {
                        1 => "the body".to_string(),
                        _ => format!("part {} ({})", k + 1, mesh.describe_part(part)),
                    }
                )));
            }
        }
        Ok(())
    }

    /// A rigid motion of `part` that no condition holds, described, if there is one: the
    /// rigid motions (translations, rotations about the part's centre, scaled by its size)
    /// restricted to the held dofs are orthogonalized in turn (modified Gram–Schmidt); one
    /// that is a combination of those before it is not held.
    fn rigid_motion_left(&self, mesh: &Mesh, part: &Part) -> Option<String> {
        let d = mesh.dim;
        let centre: [f64; 3] = std::array::from_fn(|i| 0.5 * (part.min[i] + part.max[i]));
        let size = (0..3)
            .map(|i| part.max[i] - part.min[i])
            .fold(0.0, f64::max)
            .max(f64::MIN_POSITIVE);
        let n_modes = if d == 2 { 3 } else { 6 };
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); n_modes];
        for &node in &part.nodes {
            let x: [f64; 3] = std::array::from_fn(|i| (mesh.nodes[node][i] - centre[i]) / size);
            for c in (0..d).filter(|c| self.free.is_held(d * node + c)) {
                for (m, col) in columns.iter_mut().enumerate() {
                    col.push(self.frames.to_dofs(node, rigid_mode(m, d, x))[c]);
                }
            }
        }
        let mut basis: Vec<Vec<f64>> = Vec::new();
        for (m, mut col) in columns.into_iter().enumerate() {
            for q in &basis {
                let p = dot(q, &col);
                col.iter_mut().zip(q).for_each(|(c, q)| *c -= p * q);
            }
            let norm = dot(&col, &col).sqrt();
            // Each mode has norm ~ √(held dofs) at most; 1e-8 of 1 is far below any held
            // motion of a mesh whose held nodes are not all (nearly) on one line.
            if norm <= 1e-8 {
                return Some(mode_name(m, d));
            }
            col.iter_mut().for_each(|c| *c /= norm);
            basis.push(col);
        }
        None
    }
}

/// Records `hold` on global dof `g`; a dof held twice keeps one hold when both are zero and
/// is refused otherwise.
fn put(
    holds: &mut BTreeMap<usize, Hold>,
    g: usize,
    hold: Hold,
    mesh: &Mesh,
    scene: &Scene,
) -> Result<()> {
    match holds.get(&g).copied() {
        None => {
            holds.insert(g, hold);
        }
        Some(old) if old.agrees(hold, scene) => {}
        Some(old) => {
            let (d, node) = (mesh.dim, g / mesh.dim);
            return Err(Error::input(format!(
                "{}: the node at {} lies on {} and on {}, which both hold its {} component at \
                 different values; hold each component once (in gmsh, give the shared nodes to \
                 one physical group), or write the same value in both",
                scene.path.display(),
                super::fmt_at(mesh.nodes[node], scene.mesh.model),
                old.source.describe(scene),
                hold.source.describe(scene),
                ["x", "y", "z"][g % d],
            )));
        }
    }
    Ok(())
}

/// A direction a `[[dirichlet]]` entry holds: the unit vector (a coordinate axis, or a flat
/// group's outward normal) and the index of its value.
struct Held {
    dir: [f64; 3],
    value: usize,
}

/// The directions `[[dirichlet]]` entry `i` holds on group `g`: the named axes, or the flat
/// group's outward normal.
fn directions(mesh: &Mesh, scene: &Scene, g: &Group, i: usize) -> Result<Vec<Held>> {
    let e = &scene.physics.dirichlet[i];
    let axis = |c: usize| std::array::from_fn(|k| if k == c { 1.0 } else { 0.0 });
    match &e.components {
        Components::Axes(a) => Ok(a
            .iter()
            .enumerate()
            .map(|(value, &c)| Held {
                dir: axis(c),
                value,
            })
            .collect()),
        Components::Normal => {
            let dir = flat_normal(mesh, g).map_err(|why| {
                Error::input(format!(
                    "{}: key 'dirichlet[{i}].components': [\"normal\"] on the group '{}': {why}",
                    scene.path.display(),
                    e.on
                ))
            })?;
            Ok(vec![Held { dir, value: 0 }])
        }
    }
}

/// A flat group's unit outward normal: refused when the facets' normals differ (a curved or
/// kinked group).
fn flat_normal(mesh: &Mesh, g: &Group) -> std::result::Result<[f64; 3], String> {
    let facets = mesh.boundary_facets(g);
    let Some(first) = facets.first() else {
        return Err("the group has no facets".into());
    };
    let n = first.normal;
    if let Some(f) = facets
        .iter()
        .find(|f| (0..3).any(|c| (f.normal[c] - n[c]).abs() > 1e-9))
    {
        return Err(format!(
            "the group is not flat (facet normals {} and {} differ); a normal component needs \
             one plane: prescribe coordinate components instead, or split the group into \
             flat ones",
            crate::mesh::fmt_point(n, mesh.dim),
            crate::mesh::fmt_point(f.normal, mesh.dim)
        ));
    }
    Ok(n)
}

/// A node's frame: orthonormal, right-handed axes a_0, a_1, a_2 (a_2 = e_z in 2D). The
/// node's dof k is the component u·a_k of its displacement.
pub type Axes = [[f64; 3]; 3];

/// The nodes whose dofs are components in a frame of their own: those an inclined `normal`
/// condition holds (a plane not normal to a coordinate axis). Every other node's dofs are its
/// x, y (, z) components.
#[derive(Clone, Debug, Default)]
pub struct Frames(HashMap<usize, Axes>);

impl Frames {
    /// The frames of the nodes that an inclined direction of `entries` (each `[[dirichlet]]`
    /// entry's nodes and directions) holds, unless `clamped` (increasing) holds it: the
    /// node's held directions first (a_0, and a_1 where a second one holds it), completed
    /// right-handed. A node's held directions must be parallel or perpendicular; others are
    /// refused.
    fn new(
        mesh: &Mesh,
        scene: &Scene,
        entries: &[(Vec<usize>, Vec<Held>)],
        clamped: &[usize],
    ) -> Result<Frames> {
        let d = mesh.dim;
        let inclined = |dir: [f64; 3]| (0..d).all(|c| dir[c].abs() < 1.0 - 1e-12);
        let mut at: HashMap<usize, Vec<([f64; 3], usize)>> = HashMap::new();
        for (nodes, held) in entries {
            if held.iter().any(|h| inclined(h.dir)) {
                for &node in nodes.iter().filter(|n| clamped.binary_search(n).is_err()) {
                    at.entry(node).or_default();
                }
            }
        }
        for (i, (nodes, held)) in entries.iter().enumerate() {
            for (&node, h) in nodes.iter().flat_map(|n| held.iter().map(move |h| (n, h))) {
                if let Some(list) = at.get_mut(&node) {
                    list.push((h.dir, i));
                }
            }
        }
        let mut nodes: Vec<usize> = at.keys().copied().collect();
        nodes.sort_unstable();
        let mut frames = HashMap::new();
        for node in nodes {
            let mut axes: Vec<([f64; 3], usize)> = Vec::new();
            for &(dir, i) in &at[&node] {
                match axes
                    .iter()
                    .find(|(a, _)| crate::mesh::dot(*a, dir).abs() > 1e-9)
                {
                    None => axes.push((dir, i)),
                    Some((a, _)) if crate::mesh::dot(*a, dir).abs() >= 1.0 - 1e-9 => {}
                    Some(&(a, j)) => return Err(oblique(mesh, scene, node, [(a, j), (dir, i)])),
                }
            }
            let dirs: Vec<[f64; 3]> = axes.iter().map(|&(a, _)| a).collect();
            frames.insert(node, frame(&dirs, d));
        }
        Ok(Frames(frames))
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The frame of `node`, if it has one of its own.
    pub fn of(&self, node: usize) -> Option<&Axes> {
        match self.0.is_empty() {
            true => None,
            false => self.0.get(&node),
        }
    }

    /// The dof components at `node` of the spatial vector v: v·a_k (v itself without a
    /// frame).
    pub fn to_dofs(&self, node: usize, v: [f64; 3]) -> [f64; 3] {
        match self.of(node) {
            Some(a) => a.map(|a| crate::mesh::dot(a, v)),
            None => v,
        }
    }

    /// The spatial vector Σ_k v_k a_k of the dof components v at `node` (v itself without a
    /// frame), for the first N components of both (N = 2 in the plane; zero beyond 3).
    pub fn to_space<const N: usize>(&self, node: usize, v: [f64; N]) -> [f64; N] {
        match self.of(node) {
            Some(a) => std::array::from_fn(|c| {
                let along = |k: usize| a[k].get(c).copied().unwrap_or(0.0);
                (0..N.min(3)).map(|k| v[k] * along(k)).sum()
            }),
            None => v,
        }
    }

    /// Hands the value v of spatial component c at global dof `dof` = d·node + c to the
    /// node's dofs: `put(d·node + k, (a_k)_c v)` for each k, or `put(dof, v)` without a frame.
    pub fn spread(&self, d: usize, dof: usize, v: f64, mut put: impl FnMut(usize, f64)) {
        let (node, c) = (dof / d, dof % d);
        match self.of(node) {
            Some(a) => (0..d).for_each(|k| put(d * node + k, a[k][c] * v)),
            None => put(dof, v),
        }
    }

    /// The dof component of `node` along the held direction `dir`, and the sign of `dir`
    /// along it: the frame's axis parallel to it, or without a frame the coordinate axis
    /// (where `dir` is inclined the node is clamped: any component serves to check the two
    /// holds agree).
    fn component(&self, node: usize, dir: [f64; 3], d: usize) -> (usize, f64) {
        let along = self.to_dofs(node, dir);
        let c = (0..d)
            .max_by(|&a, &b| along[a].abs().total_cmp(&along[b].abs()))
            .unwrap_or(0);
        (c, along[c].signum())
    }
}

/// The right-handed frame whose first axes are the orthonormal `dirs` (one or two).
fn frame(dirs: &[[f64; 3]], d: usize) -> Axes {
    let a0 = dirs[0];
    if d == 2 {
        return [a0, [-a0[1], a0[0], 0.0], [0.0, 0.0, 1.0]];
    }
    let a1 = match dirs.get(1) {
        Some(&a1) => a1,
        None => super::tangents(a0, 3)[0],
    };
    [a0, a1, crate::mesh::cross(a0, a1)]
}

/// Two held directions at one node that are neither parallel nor perpendicular.
fn oblique(mesh: &Mesh, scene: &Scene, node: usize, held: [([f64; 3], usize); 2]) -> Error {
    let [(a, i), (b, j)] = held;
    let on = |i: usize| Source::Dirichlet(i).describe(scene);
    Error::input(format!(
        "{}: the node at {} lies on {} and on {}, which hold the directions {} and {}: neither \
         parallel nor perpendicular, so no frame of the node holds both; make the planes meet \
         at a right angle, or clamp the nodes where they meet (mesh.groups.fixed)",
        scene.path.display(),
        super::fmt_at(mesh.nodes[node], scene.mesh.model),
        on(j),
        on(i),
        crate::mesh::fmt_point(a, mesh.dim),
        crate::mesh::fmt_point(b, mesh.dim),
    ))
}

/// Rigid mode m at the (centred, scaled) point x: translations along x, y (, z), then the
/// rotations (about z in 2D; about x, y, z in 3D).
pub fn rigid_mode(m: usize, d: usize, x: [f64; 3]) -> [f64; 3] {
    if m < d {
        let mut e = [0.0; 3];
        e[m] = 1.0;
        return e;
    }
    let mut axis = [0.0; 3];
    axis[if d == 2 { 2 } else { m - d }] = 1.0;
    crate::mesh::cross(axis, x)
}

fn mode_name(m: usize, d: usize) -> String {
    let axis = ["x", "y", "z"];
    if m < d {
        format!("a translation along {}", axis[m])
    } else {
        format!("a rotation about {}", axis[if d == 2 { 2 } else { m - d }])
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

/// `check`'s line on the conditions: each group and what it holds, the number of prescribed
/// dofs (moved to the right side of each step) and of nodes with frames of their own.
pub fn summary(scene: &Scene, n_prescribed: usize, frames: &Frames) -> String {
    let mut parts: Vec<String> = scene
        .mesh
        .groups
        .fixed
        .iter()
        .map(|g| format!("'{g}' clamped"))
        .collect();
    for e in &scene.physics.dirichlet {
        let what = match &e.components {
            Components::Normal => "normal".to_string(),
            Components::Axes(a) => a.iter().map(|&c| ["x", "y", "z"][c]).collect(),
        };
        let at = match e.written.iter().all(|v| v == "0") {
            true => " = 0".to_string(),
            false => format!(" = [{}]", e.written.join(", ")),
        };
        parts.push(format!("'{}' {what}{at}", e.on));
    }
    if parts.is_empty() {
        parts.push("none".into());
    }
    let framed = match frames.0.len() {
        0 => String::new(),
        n => format!("; {n} nodes in frames of their own (inclined planes)"),
    };
    format!(
        "{}; {n_prescribed} prescribed dofs{framed}",
        parts.join(", ")
    )
}

/// The scene's conditions for messages: "the clamped group 'Γ1'", or the groups listed.
pub fn conditions(scene: &Scene) -> String {
    let fixed = &scene.mesh.groups.fixed;
    let quoted = |v: &mut dyn Iterator<Item = &String>| {
        v.map(|g| format!("'{g}'")).collect::<Vec<_>>().join(", ")
    };
    let dirichlet = &scene.physics.dirichlet;
    match (fixed.len(), dirichlet.len()) {
        (1, 0) => format!("the clamped group '{}'", fixed[0]),
        (_, 0) => format!("the clamped groups {}", quoted(&mut fixed.iter())),
        (0, _) => format!(
            "the [[dirichlet]] groups {}",
            quoted(&mut dirichlet.iter().map(|e| &e.on))
        ),
        _ => format!(
            "the clamped groups {} and the [[dirichlet]] groups {}",
            quoted(&mut fixed.iter()),
            quoted(&mut dirichlet.iter().map(|e| &e.on))
        ),
    }
}

/// g_i(t) at the prescribed dofs, in index order. A value that is not finite is refused:
/// as bad input at the first step's t_1 = k (`time_loop::refusals` asks there before any
/// step), as a failed run later.
pub fn values(
    prescribed: &[Prescribed],
    nodes: &super::Places,
    scene: &Scene,
    t: f64,
) -> Result<Vec<f64>> {
    prescribed
        .iter()
        .map(|p| {
            let x = nodes[p.node];
            let pt = crate::expr::Point {
                x: x[0],
                y: x[1],
                z: x[2],
                t,
                ..Default::default()
            };
            let g = p.scale * scene.physics.dirichlet[p.entry].value[p.value].eval(&pt);
            if g.is_finite() {
                return Ok(g);
            }
            let what = format!(
                "{}: key 'dirichlet[{}].value[{}]' evaluates to {g} at {} at t = {t}",
                scene.path.display(),
                p.entry,
                p.value,
                super::fmt_at(x, scene.mesh.model)
            );
            Err(if t == scene.time.k() {
                Error::input(format!("{what}; a prescribed displacement must be finite"))
            } else {
                Error::solve(format!(
                    "{what}; the run stops here (the last checkpoint is kept)"
                ))
            })
        })
        .collect()
}

/// b_f −= M_fp w_p: the prescribed dofs' velocities (indices n_free.. of `w`) moved to the
/// right side of the step problem on the free dofs, M the step matrix on all dofs.
pub fn lift(m: &Sparse, n_free: usize, w: &[f64], b: &mut [f64]) {
    let m = m.as_ref();
    let (cp, ri, v) = (m.symbolic().col_ptr(), m.symbolic().row_idx(), m.val());
    for j in n_free..m.ncols() {
        for p in cp[j]..cp[j + 1] {
            if ri[p] < n_free {
                b[ri[p]] -= v[p] * w[j];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::DofIndices;
    use crate::testing::SplitMix;

    /// The searched numbering and the kept one give every dof the index that numbering
    /// them one by one gives (free first, then prescribed, each in global order), and
    /// `global` inverts it: held runs at either end, one free dof, none held, random sets.
    #[test]
    fn searched_indices_are_the_whole_numbering() {
        let mut rng = SplitMix(52);
        let mut cases: Vec<(usize, Vec<u32>, Vec<u32>)> = vec![
            (7, vec![], vec![]),
            (7, vec![0, 1, 2], vec![1]),
            (7, vec![4, 5, 6], vec![4, 6]),
            (7, vec![0, 1, 2, 3, 5, 6], vec![0, 6]),
        ];
        for _ in 0..50 {
            let n = 1 + (rng.next() % 60) as usize;
            let held: Vec<u32> = (0..n as u32)
                .filter(|_| rng.next().is_multiple_of(3))
                .collect();
            let prescribed = held
                .iter()
                .copied()
                .filter(|_| rng.next().is_multiple_of(2))
                .collect();
            if held.len() < n {
                cases.push((n, held, prescribed));
            }
        }
        for (n, held, prescribed) in cases {
            let free_dofs = (0..n).filter(|&g| !held.contains(&(g as u32)));
            let mut expected = vec![None; n];
            let order = free_dofs.chain(prescribed.iter().map(|&g| g as usize));
            order.enumerate().for_each(|(i, g)| expected[g] = Some(i));
            let searched = DofIndices::new(n, held.clone(), prescribed.clone());
            let whole = searched.clone().whole();
            for (g, &want) in expected.iter().enumerate() {
                let case = format!("n = {n}, held {held:?}, prescribed {prescribed:?}, dof {g}");
                assert_eq!(searched.get(g), want, "{case}");
                assert_eq!(whole.get(g), want, "{case}");
                assert_eq!(searched.is_held(g), held.contains(&(g as u32)), "{case}");
                if let Some(i) = want {
                    assert_eq!((searched.global(i), whole.global(i)), (g, g), "{case}");
                }
            }
            assert!(searched.signed().eq(whole.signed()));
        }
    }
}

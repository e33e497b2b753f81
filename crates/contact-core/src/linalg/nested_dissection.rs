//! Nested-dissection ordering of a sparse symmetric matrix (George, *Nested dissection of a
//! regular finite element mesh*, SIAM J. Numer. Anal. 10 (1973)), with the separators found
//! the multilevel way of METIS (Karypis & Kumar, *A fast and high quality multilevel scheme
//! for partitioning irregular graphs*, SIAM J. Sci. Comput. 20 (1998)):
//!
//! 1. **Node graph.** Rows with the same pattern (the 2 or 3 DOFs of a mesh node of a vector
//!    operator, found by hashing the patterns) are one vertex of weight their count, so the
//!    order keeps each node's DOFs together and the factor's supernodes stay whole.
//! 2. **Bisection by a vertex separator.** The graph is coarsened by heavy-edge matching
//!    until it has a few hundred vertices; there a separator is grown by breadth-first
//!    search from several start vertices (the vertices reached first until half the weight,
//!    the boundary of that region), each improved by vertex Fiduccia–Mattheyses refinement
//!    (move a separator vertex to one side, its neighbours on the other side into the
//!    separator; best gain first, hill-climbing with a roll-back to the best separator seen,
//!    sides at most 60 % of the weight), the lightest kept; it is then projected back level
//!    by level and refined again on each.
//! 3. **Recursion.** Both sides are ordered recursively, first one then the other, and the
//!    separator is numbered after them; a part of at most [`LEAF`] vertices is ordered by
//!    minimum degree on its own graph.
//!
//! Every step is linear in the edges of the graph it works on (coarsening, extraction of the
//! sides, a bounded number of refinement passes), so an ordering costs O(E log N).

use faer::sparse::SymbolicSparseColMatRef;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Parts of at most this many vertices are ordered by minimum degree instead of dissected.
pub const LEAF: usize = 128;
/// A part no bisection splits is ordered by minimum degree up to this size, else as given.
const FALLBACK_MD: usize = 2048;
/// Coarsening stops at this many vertices (or when matching no longer shrinks the graph).
const COARSEST: usize = 120;
/// Breadth-first starts tried for the separator of the coarsest graph.
const STARTS: usize = 6;
/// A side may hold at most this fraction of the weight.
const MAX_SIDE: f64 = 0.6;
/// Refinement passes per level (each stops early when it no longer improves).
const PASSES: usize = 6;

/// A graph without self loops: neighbours of v are `adj[xadj[v]..xadj[v + 1]]`, with vertex
/// and edge weights.
#[derive(Debug, Clone)]
pub struct Graph {
    pub xadj: Vec<usize>,
    pub adj: Vec<u32>,
    pub vw: Vec<u32>,
    pub ew: Vec<u32>,
}

impl Graph {
    pub fn n(&self) -> usize {
        self.vw.len()
    }

    fn nbrs(&self, v: usize) -> std::ops::Range<usize> {
        self.xadj[v]..self.xadj[v + 1]
    }

    /// The graph of unit weights with the undirected edges `edges` (both directions or one).
    pub fn from_edges(n: usize, edges: &[(usize, usize)]) -> Graph {
        let mut lists = vec![Vec::new(); n];
        for &(a, b) in edges {
            if a != b {
                lists[a].push(b as u32);
                lists[b].push(a as u32);
            }
        }
        let mut xadj = vec![0];
        let mut adj = Vec::new();
        for l in &mut lists {
            l.sort_unstable();
            l.dedup();
            adj.extend_from_slice(l);
            xadj.push(adj.len());
        }
        let ew = vec![1; adj.len()];
        Graph {
            xadj,
            adj,
            vw: vec![1; n],
            ew,
        }
    }
}

/// Where a vertex lies after a bisection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    A,
    B,
    Separator,
}

/// The fill-reducing order of the symmetric matrix whose lower (or upper) triangle has the
/// pattern `a`: row i of the reordered matrix is row `forward[i]` of the matrix.
pub fn order(a: SymbolicSparseColMatRef<'_, usize>) -> Vec<usize> {
    let (graph, dofs_of) = node_graph(a);
    let mut forward = Vec::with_capacity(a.nrows());
    for v in order_graph(&graph) {
        forward.extend(dofs_of[v].iter().copied());
    }
    forward
}

/// The node graph of the pattern `a` (one triangle of a symmetric matrix): rows with equal
/// full patterns merged. Returns the graph and each vertex's rows, ascending.
pub fn node_graph(a: SymbolicSparseColMatRef<'_, usize>) -> (Graph, Vec<Vec<usize>>) {
    let n = a.nrows();
    // The full pattern with the diagonal, rows sorted.
    let mut count = vec![1usize; n];
    for j in 0..n {
        for &i in &a.row_idx()[a.col_range(j)] {
            if i != j {
                count[i] += 1;
                count[j] += 1;
            }
        }
    }
    let mut ptr = vec![0usize; n + 1];
    for i in 0..n {
        ptr[i + 1] = ptr[i] + count[i];
    }
    let mut fill = ptr[..n].to_vec();
    let mut idx = vec![0u32; ptr[n]];
    for i in 0..n {
        idx[fill[i]] = i as u32;
        fill[i] += 1;
    }
    for j in 0..n {
        for &i in &a.row_idx()[a.col_range(j)] {
            if i != j {
                idx[fill[i]] = j as u32;
                fill[i] += 1;
                idx[fill[j]] = i as u32;
                fill[j] += 1;
            }
        }
    }
    for i in 0..n {
        idx[ptr[i]..ptr[i + 1]].sort_unstable();
    }
    let row = |i: usize| &idx[ptr[i]..ptr[i + 1]];
    // Rows with equal patterns: sort by hash, compare within a run of equal hashes.
    let hash = |r: &[u32]| {
        r.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &c| {
            (h ^ c as u64).wrapping_mul(0x0000_0100_0000_01b3)
        })
    };
    let mut keyed: Vec<(u64, usize)> = (0..n).map(|i| (hash(row(i)), i)).collect();
    keyed.sort_unstable();
    let mut vertex_of = vec![u32::MAX; n];
    let mut dofs_of: Vec<Vec<usize>> = Vec::new();
    let mut run = 0;
    while run < n {
        let mut end = run;
        while end < n && keyed[end].0 == keyed[run].0 {
            end += 1;
        }
        let first = dofs_of.len();
        for &(_, i) in &keyed[run..end] {
            match (first..dofs_of.len()).find(|&v| row(dofs_of[v][0]) == row(i)) {
                Some(v) => {
                    dofs_of[v].push(i);
                    vertex_of[i] = v as u32;
                }
                None => {
                    vertex_of[i] = dofs_of.len() as u32;
                    dofs_of.push(vec![i]);
                }
            }
        }
        run = end;
    }
    // Vertices in the order of their first row (the natural order of the nodes).
    dofs_of.sort_unstable_by_key(|d| d[0]);
    for (v, dofs) in dofs_of.iter().enumerate() {
        for &i in dofs {
            vertex_of[i] = v as u32;
        }
    }
    let nv = dofs_of.len();
    let mut xadj = vec![0];
    let mut adj = Vec::new();
    let mut mark = vec![u32::MAX; nv];
    for (v, dofs) in dofs_of.iter().enumerate() {
        mark[v] = v as u32;
        for &c in row(dofs[0]) {
            let w = vertex_of[c as usize];
            if mark[w as usize] != v as u32 {
                mark[w as usize] = v as u32;
                adj.push(w);
            }
        }
        xadj.push(adj.len());
    }
    let vw = dofs_of.iter().map(|d| d.len() as u32).collect();
    let ew = vec![1; adj.len()];
    (Graph { xadj, adj, vw, ew }, dofs_of)
}

/// The nested-dissection order of the vertices of `graph`: position i holds a vertex.
pub fn order_graph(graph: &Graph) -> Vec<usize> {
    let mut out = vec![0usize; graph.n()];
    let ids: Vec<usize> = (0..graph.n()).collect();
    dissect(graph, &ids, &mut out);
    out
}

/// Orders `graph` (whose vertex v is `ids[v]` of the original) into `out` (length n).
fn dissect(graph: &Graph, ids: &[usize], out: &mut [usize]) {
    let n = graph.n();
    if n <= LEAF {
        for (slot, v) in out.iter_mut().zip(minimum_degree(graph)) {
            *slot = ids[v];
        }
        return;
    }
    let side = bisect(graph);
    let part = |s: Side| -> Vec<usize> { (0..n).filter(|&v| side[v] == s).collect() };
    let (a, b, sep) = (part(Side::A), part(Side::B), part(Side::Separator));
    if a.len().max(b.len()) == n || sep.len() == n {
        // No progress (a clique-like part): minimum degree where that is cheap, else as is.
        let order: Vec<usize> = if n <= FALLBACK_MD {
            minimum_degree(graph)
        } else {
            (0..n).collect()
        };
        for (slot, v) in out.iter_mut().zip(order) {
            *slot = ids[v];
        }
        return;
    }
    let (out_a, rest) = out.split_at_mut(a.len());
    let (out_b, out_s) = rest.split_at_mut(b.len());
    for (vs, o) in [(&a, out_a), (&b, out_b)] {
        let (sub, sub_ids) = induced(graph, vs, ids);
        dissect(&sub, &sub_ids, o);
    }
    for (slot, &v) in out_s.iter_mut().zip(&sep) {
        *slot = ids[v];
    }
}

/// The subgraph induced by `vs`, with the original ids of its vertices.
fn induced(graph: &Graph, vs: &[usize], ids: &[usize]) -> (Graph, Vec<usize>) {
    let mut local = vec![u32::MAX; graph.n()];
    for (i, &v) in vs.iter().enumerate() {
        local[v] = i as u32;
    }
    let mut xadj = Vec::with_capacity(vs.len() + 1);
    xadj.push(0);
    let (mut adj, mut ew) = (Vec::new(), Vec::new());
    for &v in vs {
        for e in graph.nbrs(v) {
            let w = local[graph.adj[e] as usize];
            if w != u32::MAX {
                adj.push(w);
                ew.push(graph.ew[e]);
            }
        }
        xadj.push(adj.len());
    }
    let vw = vs.iter().map(|&v| graph.vw[v]).collect();
    let sub_ids = vs.iter().map(|&v| ids[v]).collect();
    (Graph { xadj, adj, vw, ew }, sub_ids)
}

/// Minimum-degree order of a small graph (exact elimination graphs as bit sets).
fn minimum_degree(graph: &Graph) -> Vec<usize> {
    let n = graph.n();
    let words = n.div_ceil(64).max(1);
    let mut adj = vec![0u64; n * words];
    for v in 0..n {
        for e in graph.nbrs(v) {
            let w = graph.adj[e] as usize;
            adj[v * words + w / 64] |= 1 << (w % 64);
        }
    }
    let mut alive = vec![true; n];
    let mut order = Vec::with_capacity(n);
    let weight = |adj: &[u64], v: usize| -> u64 {
        let mut d = 0u64;
        for (k, &word) in adj[v * words..(v + 1) * words].iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let w = k * 64 + bits.trailing_zeros() as usize;
                d += graph.vw[w] as u64;
                bits &= bits - 1;
            }
        }
        d
    };
    for _ in 0..n {
        let v = (0..n)
            .filter(|&v| alive[v])
            .min_by_key(|&v| (weight(&adj, v), v))
            .expect("a vertex is left");
        alive[v] = false;
        order.push(v);
        let row: Vec<u64> = adj[v * words..(v + 1) * words].to_vec();
        for (k, &word) in row.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                let w = k * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                for (x, r) in adj[w * words..(w + 1) * words].iter_mut().zip(&row) {
                    *x |= r;
                }
                adj[w * words + w / 64] &= !(1 << (w % 64));
                adj[w * words + v / 64] &= !(1 << (v % 64));
            }
        }
    }
    order
}

/// A vertex separator of `graph`: A and B have no edge between them (multilevel, see the
/// module doc).
pub fn bisect(graph: &Graph) -> Vec<Side> {
    // Coarsen.
    let mut levels: Vec<(Graph, Vec<u32>)> = Vec::new();
    let mut current = graph.clone();
    while current.n() > COARSEST {
        let (coarse, cmap) = coarsen(&current, levels.len() as u64);
        if coarse.n() as f64 > 0.9 * current.n() as f64 {
            break;
        }
        levels.push((std::mem::replace(&mut current, coarse), cmap));
    }
    // The coarsest graph: the best of several grown separators.
    let total: u64 = current.vw.iter().map(|&w| w as u64).sum();
    let mut best: Option<(u64, u64, Vec<Side>)> = None;
    let n = current.n();
    for s in 0..STARTS.min(n) {
        let start = if s == 0 {
            peripheral(&current, 0)
        } else {
            (s * n) / STARTS
        };
        let mut side = grow(&current, start, total);
        refine(&current, &mut side);
        let (wa, wb, ws) = weights(&current, &side);
        let key = (ws, wa.abs_diff(wb));
        if best.as_ref().is_none_or(|b| key < (b.0, b.1)) {
            best = Some((key.0, key.1, side));
        }
    }
    let mut side = best.expect("a start").2;
    // Project back and refine on each level.
    while let Some((fine, cmap)) = levels.pop() {
        side = cmap.iter().map(|&c| side[c as usize]).collect();
        refine(&fine, &mut side);
    }
    side
}

fn weights(graph: &Graph, side: &[Side]) -> (u64, u64, u64) {
    let mut w = [0u64; 3];
    for (v, s) in side.iter().enumerate() {
        w[*s as usize] += graph.vw[v] as u64;
    }
    (w[0], w[1], w[2])
}

/// A deterministic pseudo-random permutation of 0..n (xorshift keys).
fn shuffled(n: usize, seed: u64) -> Vec<usize> {
    let mut x = 0x9e37_79b9_7f4a_7c15u64 ^ seed.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    let mut keyed: Vec<(u64, usize)> = (0..n)
        .map(|i| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x, i)
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// Heavy-edge matching and the contracted graph; `cmap[v]` is v's coarse vertex.
fn coarsen(graph: &Graph, seed: u64) -> (Graph, Vec<u32>) {
    let n = graph.n();
    let mut cmap = vec![u32::MAX; n];
    let mut nc = 0u32;
    let mut fine_of: Vec<(u32, u32)> = Vec::with_capacity(n / 2 + 1);
    for v in shuffled(n, seed) {
        if cmap[v] != u32::MAX {
            continue;
        }
        let mut mate = v;
        let mut best = (0u32, u32::MAX);
        for e in graph.nbrs(v) {
            let u = graph.adj[e] as usize;
            if cmap[u] == u32::MAX && u != v {
                // Heaviest edge; among equal ones the lightest merged vertex.
                let key = (graph.ew[e], u32::MAX - graph.vw[u]);
                if mate == v || key > best {
                    best = key;
                    mate = u;
                }
            }
        }
        cmap[v] = nc;
        cmap[mate] = nc;
        fine_of.push((v as u32, mate as u32));
        nc += 1;
    }
    let nc = nc as usize;
    let mut xadj = Vec::with_capacity(nc + 1);
    xadj.push(0);
    let (mut adj, mut ew) = (Vec::new(), Vec::new());
    let mut vw = Vec::with_capacity(nc);
    let mut slot = vec![usize::MAX; nc];
    for (c, &(a, b)) in fine_of.iter().enumerate() {
        let start = adj.len();
        let members: &[u32] = if a == b { &[a][..] } else { &[a, b][..] };
        let mut w = 0;
        for &f in members {
            let f = f as usize;
            w += graph.vw[f];
            for e in graph.nbrs(f) {
                let d = cmap[graph.adj[e] as usize] as usize;
                if d == c {
                    continue;
                }
                if slot[d] >= start && slot[d] < adj.len() && adj[slot[d]] as usize == d {
                    ew[slot[d]] += graph.ew[e];
                } else {
                    slot[d] = adj.len();
                    adj.push(d as u32);
                    ew.push(graph.ew[e]);
                }
            }
        }
        vw.push(w);
        xadj.push(adj.len());
    }
    (Graph { xadj, adj, vw, ew }, cmap)
}

/// Breadth-first distances from `start` (u32::MAX where not reached) and the last vertex
/// reached.
fn bfs(graph: &Graph, start: usize) -> (Vec<u32>, usize) {
    let mut dist = vec![u32::MAX; graph.n()];
    let mut queue = std::collections::VecDeque::from([start]);
    dist[start] = 0;
    let mut last = start;
    while let Some(v) = queue.pop_front() {
        last = v;
        for e in graph.nbrs(v) {
            let u = graph.adj[e] as usize;
            if dist[u] == u32::MAX {
                dist[u] = dist[v] + 1;
                queue.push_back(u);
            }
        }
    }
    (dist, last)
}

/// A pseudo-peripheral vertex of `start`'s component (repeated farthest-vertex search).
fn peripheral(graph: &Graph, start: usize) -> usize {
    let (dist, mut far) = bfs(graph, start);
    let mut ecc = dist[far];
    for _ in 0..8 {
        let (d, f) = bfs(graph, far);
        if d[f] <= ecc {
            break;
        }
        (ecc, far) = (d[f], f);
    }
    far
}

/// Region A grown breadth first from `start` (then from unreached vertices) to half the
/// weight; the separator is A's outer boundary.
fn grow(graph: &Graph, start: usize, total: u64) -> Vec<Side> {
    let n = graph.n();
    let mut side = vec![Side::B; n];
    let mut seen = vec![false; n];
    let mut queue = std::collections::VecDeque::new();
    let mut wa = 0u64;
    let mut next_root = 0;
    let mut root = Some(start);
    'grow: while let Some(r) = root.take() {
        seen[r] = true;
        queue.push_back(r);
        while let Some(v) = queue.pop_front() {
            if 2 * wa >= total {
                break 'grow;
            }
            side[v] = Side::A;
            wa += graph.vw[v] as u64;
            for e in graph.nbrs(v) {
                let u = graph.adj[e] as usize;
                if !seen[u] {
                    seen[u] = true;
                    queue.push_back(u);
                }
            }
        }
        while next_root < n && seen[next_root] {
            next_root += 1;
        }
        if next_root < n {
            root = Some(next_root);
        }
    }
    for v in 0..n {
        if side[v] == Side::B
            && graph
                .nbrs(v)
                .any(|e| side[graph.adj[e] as usize] == Side::A)
        {
            side[v] = Side::Separator;
        }
    }
    side
}

/// Vertex Fiduccia–Mattheyses refinement of the separator `side` (see the module doc).
fn refine(graph: &Graph, side: &mut [Side]) {
    let n = graph.n();
    let total: u64 = graph.vw.iter().map(|&w| w as u64).sum();
    let limit = ((MAX_SIDE * total as f64) as u64).max(1);
    let mut stamp = vec![0u32; n];
    let mut locked = vec![false; n];
    // Gain of moving separator vertex v to side `to`: its weight less that of its
    // neighbours on the other side.
    let gain = |side: &[Side], v: usize, to: Side| -> i64 {
        let other = if to == Side::A { Side::B } else { Side::A };
        let pulled: i64 = graph
            .nbrs(v)
            .filter(|&e| side[graph.adj[e] as usize] == other)
            .map(|e| graph.vw[graph.adj[e] as usize] as i64)
            .sum();
        graph.vw[v] as i64 - pulled
    };
    for _ in 0..PASSES {
        let (mut wa, mut wb, mut ws) = weights(graph, side);
        let mut best = (ws, wa.abs_diff(wb));
        let mut best_len = 0usize;
        // Moves: (vertex, the side it went to, range of the pulled vertices in `pulled`).
        let mut moves: Vec<(usize, Side, usize, usize)> = Vec::new();
        let mut pulled: Vec<usize> = Vec::new();
        let mut heaps = [BinaryHeap::new(), BinaryHeap::new()];
        locked.iter_mut().for_each(|l| *l = false);
        let push = |heaps: &mut [BinaryHeap<(i64, Reverse<usize>, u32)>; 2],
                    side: &[Side],
                    stamp: &mut [u32],
                    v: usize| {
            stamp[v] += 1;
            heaps[0].push((gain(side, v, Side::A), Reverse(v), stamp[v]));
            heaps[1].push((gain(side, v, Side::B), Reverse(v), stamp[v]));
        };
        for v in 0..n {
            if side[v] == Side::Separator {
                push(&mut heaps, side, &mut stamp, v);
            }
        }
        let stall_limit = (n / 100).clamp(25, 400);
        let mut stall = 0;
        loop {
            // The valid top of each heap.
            let mut tops = [None, None];
            for (k, heap) in heaps.iter_mut().enumerate() {
                while let Some(&(g, Reverse(v), s)) = heap.peek() {
                    if s == stamp[v] && side[v] == Side::Separator && !locked[v] {
                        tops[k] = Some((g, v));
                        break;
                    }
                    heap.pop();
                }
            }
            // The better move that keeps the balance; gain ties go to the lighter side.
            let mut choice = None;
            let mut order = [0usize, 1];
            let better_b = match (tops[0], tops[1]) {
                (Some((ga, _)), Some((gb, _))) => gb > ga || (gb == ga && wb < wa),
                (None, Some(_)) => true,
                _ => false,
            };
            if better_b {
                order = [1, 0];
            }
            for k in order {
                if let Some((_, v)) = tops[k] {
                    let to = if k == 0 { Side::A } else { Side::B };
                    let other = if k == 0 { Side::B } else { Side::A };
                    let w_to = if k == 0 { wa } else { wb };
                    if w_to + graph.vw[v] as u64 <= limit {
                        choice = Some((v, to, other));
                        break;
                    }
                    heaps[k].pop();
                }
            }
            let Some((v, to, other)) = choice else {
                if tops.iter().all(Option::is_none) {
                    break;
                }
                continue;
            };
            // Apply.
            let first = pulled.len();
            side[v] = to;
            locked[v] = true;
            ws -= graph.vw[v] as u64;
            *(if to == Side::A { &mut wa } else { &mut wb }) += graph.vw[v] as u64;
            for e in graph.nbrs(v) {
                let u = graph.adj[e] as usize;
                if side[u] == other {
                    side[u] = Side::Separator;
                    pulled.push(u);
                    ws += graph.vw[u] as u64;
                    *(if other == Side::A { &mut wa } else { &mut wb }) -= graph.vw[u] as u64;
                }
            }
            moves.push((v, to, first, pulled.len()));
            // Gains that changed: the new separator vertices, and separator neighbours of v
            // and of them.
            for e in graph.nbrs(v) {
                let u = graph.adj[e] as usize;
                if side[u] == Side::Separator && !locked[u] {
                    push(&mut heaps, side, &mut stamp, u);
                }
            }
            for &u in &pulled[first..] {
                for e in graph.nbrs(u) {
                    let x = graph.adj[e] as usize;
                    if side[x] == Side::Separator && !locked[x] {
                        push(&mut heaps, side, &mut stamp, x);
                    }
                }
            }
            let key = (ws, wa.abs_diff(wb));
            if key < best {
                best = key;
                best_len = moves.len();
                stall = 0;
            } else {
                stall += 1;
                if stall > stall_limit {
                    break;
                }
            }
        }
        // Roll back to the best separator seen.
        while moves.len() > best_len {
            let (v, to, first, last) = moves.pop().expect("a move");
            let other = if to == Side::A { Side::B } else { Side::A };
            for &u in &pulled[first..last] {
                side[u] = other;
            }
            side[v] = Side::Separator;
        }
        if best_len == 0 {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The graph of an nx × ny × nz grid with the 3D Kuhn diagonals (edges along the
    /// monotone steps of the 6 tetrahedra of each cube).
    pub(crate) fn kuhn_grid(nx: usize, ny: usize, nz: usize) -> Graph {
        let id = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
        let mut edges = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    for (di, dj, dk) in [
                        (1, 0, 0),
                        (0, 1, 0),
                        (0, 0, 1),
                        (1, 1, 0),
                        (1, 0, 1),
                        (0, 1, 1),
                        (1, 1, 1),
                    ] {
                        if i + di < nx && j + dj < ny && k + dk < nz {
                            edges.push((id(i, j, k), id(i + di, j + dj, k + dk)));
                        }
                    }
                }
            }
        }
        Graph::from_edges(nx * ny * nz, &edges)
    }

    #[test]
    fn separator_separates_and_is_near_a_plane() {
        let g = kuhn_grid(20, 20, 20);
        let side = bisect(&g);
        for v in 0..g.n() {
            for e in g.nbrs(v) {
                let u = g.adj[e] as usize;
                assert!(
                    !(side[v] == Side::A && side[u] == Side::B),
                    "edge {v}–{u} crosses the separator"
                );
            }
        }
        let (wa, wb, ws) = weights(&g, &side);
        assert!(wa > 0 && wb > 0);
        assert!(wa.max(wb) as f64 <= MAX_SIDE * g.n() as f64);
        // A plane of the 20³ grid has 400 vertices; a separator of the Kuhn graph must
        // also cut the diagonals, so a flat one has 400. Allow twice that.
        assert!(ws <= 800, "separator of {ws} vertices");
    }

    #[test]
    fn order_is_a_permutation() {
        for g in [kuhn_grid(13, 9, 7), kuhn_grid(1, 1, 1), kuhn_grid(40, 3, 2)] {
            let mut o = order_graph(&g);
            o.sort_unstable();
            assert_eq!(o, (0..g.n()).collect::<Vec<_>>());
        }
        // Disconnected: two grids side by side.
        let mut edges = Vec::new();
        let a = kuhn_grid(8, 8, 8);
        for v in 0..a.n() {
            for e in a.nbrs(v) {
                let u = a.adj[e] as usize;
                edges.push((v, u));
                edges.push((v + a.n(), u + a.n()));
            }
        }
        let g = Graph::from_edges(2 * a.n(), &edges);
        let mut o = order_graph(&g);
        o.sort_unstable();
        assert_eq!(o, (0..g.n()).collect::<Vec<_>>());
    }

    #[test]
    fn rows_of_a_node_are_one_vertex() {
        // A block-tridiagonal matrix with 3 × 3 dense blocks: 4 nodes of 3 DOFs in a chain.
        let mut t = Vec::new();
        for a in 0..4usize {
            for b in a.saturating_sub(1)..(a + 2).min(4) {
                for r in 0..3 {
                    for c in 0..3 {
                        t.push((
                            3 * a + r,
                            3 * b + c,
                            if a == b && r == c { 4.0 } else { -0.1 },
                        ));
                    }
                }
            }
        }
        let csr = crate::linalg::Csr::from_triplets(12, 12, t);
        let lower = csr.lower_csc();
        let (g, dofs) = node_graph(lower.as_ref().symbolic());
        assert_eq!(g.n(), 4);
        assert_eq!(
            dofs,
            vec![vec![0, 1, 2], vec![3, 4, 5], vec![6, 7, 8], vec![9, 10, 11]]
        );
        assert_eq!(g.vw, vec![3; 4]);
        let mut f = order(lower.as_ref().symbolic());
        f.sort_unstable();
        assert_eq!(f, (0..12).collect::<Vec<_>>());
    }

    /// (L + I) ⊗ M on the Kuhn grid: L its graph Laplacian, M a dense SPD 3 × 3 block, so the
    /// pattern is that of a P1 vector operator (3 DOFs per node, dense node blocks).
    fn kuhn_operator(nx: usize, ny: usize, nz: usize) -> crate::linalg::Csr {
        let g = kuhn_grid(nx, ny, nz);
        let m = |r: usize, c: usize| if r == c { 2.0 } else { 0.5 };
        let mut t = Vec::new();
        for v in 0..g.n() {
            let degree = g.nbrs(v).len() as f64;
            for r in 0..3 {
                for c in 0..3 {
                    t.push((3 * v + r, 3 * v + c, (degree + 1.0) * m(r, c)));
                    for e in g.nbrs(v) {
                        t.push((3 * v + r, 3 * g.adj[e] as usize + c, -m(r, c)));
                    }
                }
            }
        }
        crate::linalg::Csr::from_triplets(3 * g.n(), 3 * g.n(), t)
    }

    #[test]
    fn less_fill_than_amd_on_a_kuhn_box_and_the_factor_solves() {
        use crate::linalg::cholesky::{Cholesky, Ordering};
        let a = kuhn_operator(20, 20, 20);
        let lower = a.lower_csc();
        let amd = Cholesky::by(lower.as_ref(), Ordering::Amd).unwrap();
        let mut nd = Cholesky::by(lower.as_ref(), Ordering::NestedDissection).unwrap();
        let ratio = amd.nnz_l() as f64 / nd.nnz_l() as f64;
        // Measured: nnz(L) 18.2 M with AMD, 13.3 M with nested dissection (AMD/ND = 1.37);
        // the assertion leaves a margin.
        assert!(ratio > 1.25, "AMD/ND fill {ratio}");
        let chosen = Cholesky::least_fill(lower.as_ref()).unwrap();
        assert_eq!(chosen.ordering(), Ordering::NestedDissection);
        assert_eq!(chosen.nnz_l(), nd.nnz_l());
        // The factor solves A x = b to round-off.
        let x: Vec<f64> = (0..a.nrows).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut b = vec![0.0; a.nrows];
        a.mul_vec(&x, &mut b);
        let mut y = b.clone();
        nd.solve_in_place(&mut y);
        let mut r = vec![0.0; a.nrows];
        a.mul_vec(&y, &mut r);
        let res = r
            .iter()
            .zip(&b)
            .fold(0.0f64, |m, (u, v)| m.max((u - v).abs()));
        let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(res <= 1e-12 * scale, "residual {res} of {scale}");
    }
}

//! A minimum cut of a two-label energy on a pixel grid, by Boykov and Kolmogorov's max-flow
//! algorithm ("An Experimental Comparison of Min-Cut/Max-Flow Algorithms for Energy
//! Minimization in Vision", PAMI 2004): two search trees grown from the terminals, augmented
//! along the paths where they meet, their orphans adopted rather than the trees rebuilt.
//! It is the algorithm made for graphs like these (4-connected, short paths, many of them),
//! a few times faster there than push-relabel.
//!
//! The energy: Σ_p D_p(l_p) + Σ_{p~q} w_pq·[l_p ≠ l_q] with l in {A, B}, D ≥ 0, w ≥ 0.

const NONE: u32 = u32::MAX;
/// The node hangs from its terminal directly.
const TERMINAL: u32 = u32::MAX - 1;
/// The node lost its parent arc this augmentation.
const ORPHAN: u32 = u32::MAX - 2;

/// A pixel grid's cut problem: per pixel the cost of each label, per neighbour pair the cost
/// of telling them apart.
pub struct GridCut {
    width: usize,
    height: usize,
    /// Residual capacity to the terminals: > 0 from the source (label A's side), < 0 to the
    /// sink.
    terminal: Vec<f32>,
    /// Per pixel, four arcs: right, down, left, up (to the neighbour; 0 at the border).
    arcs: Vec<[f32; 4]>,
}

/// The arc from pixel i in direction d goes to `neighbour(i, d)`; its reverse is the
/// neighbour's arc in direction (d + 2) % 4.
const REVERSE: [usize; 4] = [2, 3, 0, 1];

// The four directions index both the arcs and REVERSE: a range reads plainer than zips.
#[allow(clippy::needless_range_loop)]
impl GridCut {
    pub fn new(width: usize, height: usize) -> GridCut {
        GridCut {
            width,
            height,
            terminal: vec![0.0; width * height],
            arcs: vec![[0.0; 4]; width * height],
        }
    }

    /// What label A and label B cost at pixel `i` (≥ 0).
    pub fn set_costs(&mut self, i: usize, cost_a: f32, cost_b: f32) {
        // Paying D(A) means cutting the sink arc; paying D(B), the source arc.
        self.terminal[i] = cost_b - cost_a;
    }

    /// What it costs when pixel `i` and its right (`down` false) or lower neighbour differ.
    pub fn set_pair(&mut self, i: usize, down: bool, w: f32) {
        let (d, j) = if down {
            (1, i + self.width)
        } else {
            (0, i + 1)
        };
        self.arcs[i][d] = w;
        self.arcs[j][REVERSE[d]] = w;
    }

    /// Whether `child` (the neighbour of `parent` in direction `d`) can hang from `parent` in
    /// the source's tree (flow parent → child) or the sink's (flow child → parent).
    fn tree_arc(&self, parent: usize, d: usize, child: usize, sink: bool) -> bool {
        if sink {
            self.arcs[child][REVERSE[d]] > 0.0
        } else {
            self.arcs[parent][d] > 0.0
        }
    }

    fn neighbour(&self, i: usize, d: usize) -> Option<usize> {
        let (x, y) = (i % self.width, i / self.width);
        match d {
            0 => (x + 1 < self.width).then(|| i + 1),
            1 => (y + 1 < self.height).then(|| i + self.width),
            2 => (x > 0).then(|| i - 1),
            _ => (y > 0).then(|| i - self.width),
        }
    }

    /// The minimum cut: true where a pixel takes label A.
    pub fn solve(mut self) -> Vec<bool> {
        let n = self.width * self.height;
        let mut s = Search {
            parent: vec![NONE; n],
            sink: vec![false; n],
            stamp: vec![0; n],
            dist: vec![0; n],
            active: std::collections::VecDeque::new(),
            queued: vec![false; n],
            orphans: Vec::new(),
            time: 1,
        };
        for i in 0..n {
            if self.terminal[i] != 0.0 {
                s.parent[i] = TERMINAL;
                s.sink[i] = self.terminal[i] < 0.0;
                s.stamp[i] = 0;
                s.dist[i] = 1;
                s.activate(i);
            }
        }
        let mut current: Option<usize> = None;
        loop {
            let i = match current.take() {
                Some(i) if s.parent[i] != NONE => i,
                _ => match s.next_active() {
                    Some(i) => i,
                    None => break,
                },
            };
            // Grow the tree of i until it touches the other tree.
            let mut meeting = None;
            for d in 0..4 {
                let Some(j) = self.neighbour(i, d) else {
                    continue;
                };
                if !self.tree_arc(i, d, j, s.sink[i]) {
                    continue;
                }
                if s.parent[j] == NONE {
                    s.sink[j] = s.sink[i];
                    s.parent[j] = REVERSE[d] as u32;
                    s.stamp[j] = s.stamp[i];
                    s.dist[j] = s.dist[i] + 1;
                    s.activate(j);
                } else if s.sink[j] != s.sink[i] {
                    meeting = Some(if s.sink[i] { (j, REVERSE[d]) } else { (i, d) });
                    break;
                } else if s.stamp[j] <= s.stamp[i] && s.dist[j] > s.dist[i] {
                    // j's path is longer than one through i: hang it from i.
                    s.parent[j] = REVERSE[d] as u32;
                    s.stamp[j] = s.stamp[i];
                    s.dist[j] = s.dist[i] + 1;
                }
            }
            s.time += 1;
            let Some((from, d)) = meeting else {
                continue;
            };
            // i stays active: it may meet the other tree again.
            current = Some(i);
            self.augment(&mut s, from, d);
            self.adopt(&mut s);
        }
        (0..n).map(|i| s.parent[i] != NONE && !s.sink[i]).collect()
    }

    /// Push the bottleneck along source → `from` → (arc d) → sink.
    fn augment(&mut self, s: &mut Search, from: usize, d: usize) {
        let to = self.neighbour(from, d).expect("the meeting arc has a head");
        let mut bottleneck = self.arcs[from][d];
        // The source side: each node receives from its parent.
        let mut i = from;
        loop {
            let p = s.parent[i];
            if p == TERMINAL {
                bottleneck = bottleneck.min(self.terminal[i]);
                break;
            }
            let j = self
                .neighbour(i, p as usize)
                .expect("a parent arc has a head");
            bottleneck = bottleneck.min(self.arcs[j][REVERSE[p as usize]]);
            i = j;
        }
        let mut i = to;
        loop {
            let p = s.parent[i];
            if p == TERMINAL {
                bottleneck = bottleneck.min(-self.terminal[i]);
                break;
            }
            bottleneck = bottleneck.min(self.arcs[i][p as usize]);
            i = self
                .neighbour(i, p as usize)
                .expect("a parent arc has a head");
        }
        self.arcs[from][d] -= bottleneck;
        self.arcs[to][REVERSE[d]] += bottleneck;
        let mut i = from;
        loop {
            let p = s.parent[i];
            if p == TERMINAL {
                self.terminal[i] -= bottleneck;
                if self.terminal[i] <= 0.0 {
                    self.terminal[i] = 0.0;
                    s.orphan(i);
                }
                break;
            }
            let j = self
                .neighbour(i, p as usize)
                .expect("a parent arc has a head");
            self.arcs[j][REVERSE[p as usize]] -= bottleneck;
            self.arcs[i][p as usize] += bottleneck;
            if self.arcs[j][REVERSE[p as usize]] <= 0.0 {
                self.arcs[j][REVERSE[p as usize]] = 0.0;
                s.orphan(i);
            }
            i = j;
        }
        let mut i = to;
        loop {
            let p = s.parent[i];
            if p == TERMINAL {
                self.terminal[i] += bottleneck;
                if self.terminal[i] >= 0.0 {
                    self.terminal[i] = 0.0;
                    s.orphan(i);
                }
                break;
            }
            let j = self
                .neighbour(i, p as usize)
                .expect("a parent arc has a head");
            self.arcs[i][p as usize] -= bottleneck;
            self.arcs[j][REVERSE[p as usize]] += bottleneck;
            if self.arcs[i][p as usize] <= 0.0 {
                self.arcs[i][p as usize] = 0.0;
                s.orphan(i);
            }
            i = j;
        }
    }

    /// Find each orphan a parent in its own tree whose path still reaches the terminal, or
    /// free it (and orphan its children).
    fn adopt(&mut self, s: &mut Search) {
        while let Some(i) = s.orphans.pop() {
            let sink = s.sink[i];
            let mut best: Option<(usize, u32)> = None;
            for d in 0..4 {
                let Some(j) = self.neighbour(i, d) else {
                    continue;
                };
                if s.sink[j] != sink || s.parent[j] == NONE {
                    continue;
                }
                if !self.tree_arc(j, REVERSE[d], i, sink) {
                    continue;
                }
                if let Some(dist) = self.origin_distance(s, j)
                    && best.is_none_or(|(_, b)| dist < b)
                {
                    best = Some((d, dist));
                }
            }
            match best {
                Some((d, dist)) => {
                    s.parent[i] = d as u32;
                    s.stamp[i] = s.time;
                    s.dist[i] = dist + 1;
                }
                None => {
                    s.parent[i] = NONE;
                    for d in 0..4 {
                        let Some(j) = self.neighbour(i, d) else {
                            continue;
                        };
                        if s.sink[j] != sink || s.parent[j] == NONE {
                            continue;
                        }
                        if self.tree_arc(j, REVERSE[d], i, sink) {
                            s.activate(j);
                        }
                        let pj = s.parent[j];
                        if pj != TERMINAL
                            && pj != ORPHAN
                            && self.neighbour(j, pj as usize) == Some(i)
                        {
                            s.orphan(j);
                        }
                    }
                }
            }
        }
    }

    /// How far `j` is from its terminal along valid parents, or `None` when its path runs
    /// into an orphan or a free node; nodes on a valid path get this time's stamp.
    fn origin_distance(&self, s: &mut Search, j: usize) -> Option<u32> {
        let mut steps = 0u32;
        let mut k = j;
        let found = loop {
            if s.stamp[k] == s.time {
                break Some(steps + s.dist[k]);
            }
            match s.parent[k] {
                TERMINAL => {
                    s.stamp[k] = s.time;
                    s.dist[k] = 1;
                    break Some(steps + 1);
                }
                ORPHAN | NONE => break None,
                p => {
                    steps += 1;
                    k = self
                        .neighbour(k, p as usize)
                        .expect("a parent arc has a head");
                }
            }
        }?;
        // Stamp the path so later searches stop early.
        let mut d = found;
        let mut k = j;
        while s.stamp[k] != s.time {
            s.stamp[k] = s.time;
            s.dist[k] = d;
            d -= 1;
            k = self
                .neighbour(k, s.parent[k] as usize)
                .expect("a parent arc has a head");
        }
        Some(found)
    }
}

/// The search trees' state.
struct Search {
    /// Per node: the arc direction to its parent, TERMINAL, ORPHAN or NONE (free).
    parent: Vec<u32>,
    /// In the sink's tree (else the source's, when it has a parent).
    sink: Vec<bool>,
    stamp: Vec<u32>,
    dist: Vec<u32>,
    active: std::collections::VecDeque<usize>,
    queued: Vec<bool>,
    orphans: Vec<usize>,
    time: u32,
}

impl Search {
    fn activate(&mut self, i: usize) {
        if !self.queued[i] {
            self.queued[i] = true;
            self.active.push_back(i);
        }
    }

    fn next_active(&mut self) -> Option<usize> {
        while let Some(i) = self.active.pop_front() {
            self.queued[i] = false;
            if self.parent[i] != NONE {
                return Some(i);
            }
        }
        None
    }

    fn orphan(&mut self, i: usize) {
        self.parent[i] = ORPHAN;
        self.orphans.push(i);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn energy(w: usize, unary: &[(f32, f32)], pairs: &[(usize, bool, f32)], l: &[bool]) -> f32 {
        let mut e: f32 = unary
            .iter()
            .zip(l)
            .map(|(&(a, b), &la)| if la { a } else { b })
            .sum();
        for &(i, down, c) in pairs {
            let j = if down { i + w } else { i + 1 };
            if l[i] != l[j] {
                e += c;
            }
        }
        e
    }

    #[test]
    fn the_cut_is_the_minimum_on_small_random_grids() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for trial in 0..300 {
            let (w, h) = (rng.random_range(1..=4usize), rng.random_range(1..=4usize));
            let n = w * h;
            let unary: Vec<(f32, f32)> = (0..n)
                .map(|_| {
                    // Whole numbers, so the energies compare exactly.
                    (rng.random_range(0..6) as f32, rng.random_range(0..6) as f32)
                })
                .collect();
            let mut pairs = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    if x + 1 < w {
                        pairs.push((i, false, rng.random_range(0..5) as f32));
                    }
                    if y + 1 < h {
                        pairs.push((i, true, rng.random_range(0..5) as f32));
                    }
                }
            }
            let mut cut = GridCut::new(w, h);
            for (i, &(a, b)) in unary.iter().enumerate() {
                cut.set_costs(i, a, b);
            }
            for &(i, down, c) in &pairs {
                cut.set_pair(i, down, c);
            }
            let labels = cut.solve();
            let got = energy(w, &unary, &pairs, &labels);
            let best = (0..1u32 << n)
                .map(|m| {
                    let l: Vec<bool> = (0..n).map(|k| m >> k & 1 == 1).collect();
                    energy(w, &unary, &pairs, &l)
                })
                .fold(f32::INFINITY, f32::min);
            assert_eq!(got, best, "trial {trial}: {w}x{h}");
        }
    }

    #[test]
    fn smoothing_removes_an_isolated_pixel() {
        let (w, h) = (9, 9);
        let mut cut = GridCut::new(w, h);
        for i in 0..w * h {
            // Everything prefers A, except the centre, weakly.
            let (a, b) = if i == 40 { (1.0, 0.0) } else { (0.0, 1.0) };
            cut.set_costs(i, a, b);
        }
        for i in 0..w * h {
            if i % w + 1 < w {
                cut.set_pair(i, false, 0.5);
            }
            if i / w + 1 < h {
                cut.set_pair(i, true, 0.5);
            }
        }
        assert!(cut.solve().iter().all(|&a| a));
    }
}

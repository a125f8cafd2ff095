//! The accumulators of merge events: per chunk of light paths ([`ChunkScratch`], handing over a
//! [`ChunkTally`]), then per iteration ([`IterationTally`], with its moment vector). What is
//! tallied per strategy — the catalogue of per-path strategies and the merge techniques — is
//! [`super::strategies`]'s; this file only sums.
//!
//! Every merge event (light path i, camera path j, plane m) adds its contribution C_m to the cell
//! of its join path, and w·C_m to each per-path strategy. Chunks tally into a reusable dense
//! scratch and hand over only the cells they touched; an iteration adds its chunks' tallies in
//! chunk order, so the floating-point sums do not depend on which thread ran which chunk.
//!
//! Contributions are tallied without the 1/(N_F·N_B) of docs/model.md's C_s; [`IterationTally`]
//! applies it once per iteration.

use super::layout::Layout;
use super::strategies::{PathStrategy, Technique};
use crate::sim::math::rng::{StreamRng, uniform};
use crate::sim::model::config::SimConfig;

/// The four blocks of an iteration's pairs when its light and camera paths are split in halves
/// (noise components, `stats::components`): block 2·h_light + h_camera.
pub const BLOCKS: usize = 4;

/// Per-path strategy sums of each block.
pub type BlockStrategies = [[f64; PathStrategy::COUNT]; BLOCKS];

/// The camera paths a merge pairs its light path with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraPaths {
    /// Camera path j (plane 2 and 3 merges).
    One(u32),
    /// All N_B at once (a plane-1 merge at the shared pixel): half of its sum goes to each camera
    /// half, which holds N_B/2 of them.
    All,
}

/// Dense per-chunk accumulator, reused across chunks by one worker.
#[derive(Debug, Clone)]
pub struct ChunkScratch {
    /// Σ C per slot m·K + α.
    sums: Vec<f64>,
    /// Merge events per slot.
    counts: Vec<u64>,
    /// Slots with a non-zero count, in first-touch order.
    touched: Vec<u32>,
    strategies: [f64; PathStrategy::COUNT],
    merges: [u64; 3],
    /// With noise components: Σ C per block and slot, at `BLOCKS·slot + block` (empty without).
    blocks: Vec<f64>,
    block_strategies: BlockStrategies,
    /// The half (0 or 1) of the light path being merged.
    light_half: usize,
    /// The restricted engine's coin stream of the current iteration (with noise components).
    coins: Option<StreamRng>,
    /// The cell and weights of recent plane-3 merges, camera path j in slot j mod
    /// [`PLANE3_SLOTS`] (see [`ChunkScratch::plane3_weights`]).
    plane3: Box<[Plane3Weights; PLANE3_SLOTS]>,
    /// One scratch per smaller radius the configuration tallies ([`SimConfig::radii`]), in its
    /// order: the merges within R′ recorded again with R′'s kernel and weights.
    pub(crate) radii: Vec<ChunkScratch>,
}

/// Slots of the plane-3 weight cache: one per camera path up to 256 (the paper has 100); with more
/// camera paths, paths 256 apart share a slot. A fixed size, so that the cache neither grows with
/// N_B (10⁶ camera paths would have cost ~100 MB a worker) nor allocates in the merge loop.
const PLANE3_SLOTS: usize = 256;

/// A camera's plane-3 merge: its join path is the camera's (x2c, x3c) whatever the light path, so
/// its cell and weights depend on the light path only through the light's start density — one of
/// a few values (the rings' levels). A camera in the bright spot merges with hundreds of light
/// paths an iteration; their cells and weights are computed once.
#[derive(Debug, Clone, Copy)]
struct Plane3Weights {
    /// The camera set ([`super::camera::CameraSet::generation`]); 0: never filled.
    generation: u64,
    /// The camera path within the set.
    camera: u32,
    /// The light's start density, as bits.
    light_start: u64,
    cell: usize,
    weights: [f64; PathStrategy::COUNT],
}

/// What one chunk hands to its iteration: the touched slots in slot order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChunkTally {
    /// (slot m·K + α, Σ C, events).
    pub entries: Vec<(u32, f64, u64)>,
    /// Σ w·C of each per-path strategy over the chunk (not normalised).
    pub strategies: [f64; PathStrategy::COUNT],
    /// Merge events per plane (plane-1 hits counted once per light path).
    pub merges: [u64; 3],
    /// With noise components: the block sums of each entry, in the same order (empty without).
    pub blocks: Vec<[f64; BLOCKS]>,
    /// With noise components: Σ w·C of each per-path strategy per block (zeros without).
    pub block_strategies: BlockStrategies,
    /// The same chunk's tally at each smaller radius of the configuration, in its order.
    pub radii: Vec<ChunkTally>,
}

impl ChunkScratch {
    /// A scratch for a grid of `cells` cells.
    pub fn new(cells: usize) -> Self {
        Self {
            sums: vec![0.0; 3 * cells],
            counts: vec![0; 3 * cells],
            touched: Vec::new(),
            strategies: [0.0; PathStrategy::COUNT],
            merges: [0; 3],
            blocks: Vec::new(),
            block_strategies: [[0.0; PathStrategy::COUNT]; BLOCKS],
            light_half: 0,
            coins: None,
            plane3: Box::new(
                [Plane3Weights {
                    generation: 0,
                    camera: 0,
                    light_start: 0,
                    cell: 0,
                    weights: [0.0; PathStrategy::COUNT],
                }; PLANE3_SLOTS],
            ),
            radii: Vec::new(),
        }
    }

    /// The cell and weights of a plane-3 merge of camera `camera` of the camera set `generation`
    /// with a light path of start density `light_start`: `compute()` unless the camera's previous
    /// plane-3 merge in its slot was this one's camera with the same set and density (then the same
    /// values, bit for bit).
    #[inline]
    pub fn plane3_weights(
        &mut self,
        generation: u64,
        camera: u32,
        light_start: f64,
        compute: impl FnOnce() -> (usize, [f64; PathStrategy::COUNT]),
    ) -> (usize, [f64; PathStrategy::COUNT]) {
        let entry = &mut self.plane3[camera as usize % PLANE3_SLOTS];
        if entry.generation != generation || entry.camera != camera || entry.light_start != light_start.to_bits() {
            let (cell, weights) = compute();
            *entry = Plane3Weights { generation, camera, light_start: light_start.to_bits(), cell, weights };
        }
        (entry.cell, entry.weights)
    }

    /// A scratch for `config`'s grid that also sums the noise components' blocks if it keeps them.
    pub fn for_config(config: &SimConfig) -> Self {
        let cells = config.cells.len();
        let mut scratch = Self::new(cells);
        if config.noise_components {
            scratch.blocks = vec![0.0; BLOCKS * 3 * cells];
        }
        scratch.radii = config.radii.iter().map(Self::for_config).collect();
        scratch
    }

    /// The half (0 or 1) of the light path whose merges follow: the brute force alternates by index,
    /// the restricted engine tosses a fair coin per kept path (which splits its Poisson process
    /// into two independent ones of half the intensity).
    #[inline]
    pub fn set_light_half(&mut self, half: usize) {
        self.light_half = half & 1;
        for sub in &mut self.radii {
            sub.light_half = self.light_half;
        }
    }

    /// Whether this scratch sums the noise components' blocks.
    pub fn keeps_blocks(&self) -> bool {
        !self.blocks.is_empty()
    }

    /// The coin stream for [`ChunkScratch::toss_light_half`] in the iteration that follows.
    pub fn set_coins(&mut self, coins: Option<StreamRng>) {
        self.coins = coins;
    }

    /// Puts the next light path in a half by a fair coin from the coin stream (a no-op without
    /// one): marking each point of a Poisson process independently with probability ½ gives two
    /// independent Poisson processes of half the intensity (the marking theorem), which is what
    /// the noise components' estimators need of the restricted engine's light paths.
    #[inline]
    pub fn toss_light_half(&mut self) {
        if let Some(coins) = &mut self.coins {
            let half = usize::from(uniform(coins) < 0.5);
            self.set_light_half(half);
        }
    }

    /// Records one merge event: contribution `c` by `technique`, in cell `cell` of a grid of
    /// `cells` cells, with the per-path strategy weights `weights`, pairing the current light path
    /// with `cameras`.
    #[inline]
    pub fn record(
        &mut self,
        technique: Technique,
        cell: usize,
        cells: usize,
        c: f64,
        weights: &[f64; PathStrategy::COUNT],
        cameras: CameraPaths,
    ) {
        let slot = technique.index() * cells + cell;
        if self.counts[slot] == 0 {
            self.touched.push(slot as u32);
        }
        self.sums[slot] += c;
        self.counts[slot] += 1;
        for (acc, w) in self.strategies.iter_mut().zip(weights) {
            *acc += w * c;
        }
        if !self.blocks.is_empty() {
            let first = BLOCKS * slot + 2 * self.light_half;
            // Camera path j is in half j mod 2 (camera paths are i.i.d., so any fixed split is fair).
            let halves: [(usize, f64); 2] = match cameras {
                CameraPaths::One(j) => [((j & 1) as usize, c), (0, 0.0)],
                CameraPaths::All => [(0, 0.5 * c), (1, 0.5 * c)],
            };
            for (h, v) in halves {
                self.blocks[first + h] += v;
                for (acc, w) in self.block_strategies[2 * self.light_half + h].iter_mut().zip(weights) {
                    *acc += w * v;
                }
            }
        }
    }

    /// Counts a merge event at `plane` (a plane-1 hit counts once per light path, although it merges
    /// with all N_B camera paths at the shared pixel).
    #[inline]
    pub fn count_merge(&mut self, technique: Technique) {
        self.merges[technique.index()] += 1;
    }

    /// Hands over the chunk's tally and resets the scratch for the next chunk.
    pub fn take(&mut self) -> ChunkTally {
        let mut tally = ChunkTally::default();
        self.take_into(&mut tally);
        tally
    }

    /// [`ChunkScratch::take`] into `tally`, reusing its buffer (the restricted engine's worker
    /// keeps one across iterations, so that none allocates).
    pub fn take_into(&mut self, tally: &mut ChunkTally) {
        tally.entries.clear();
        tally.blocks.clear();
        tally.strategies = self.strategies;
        tally.merges = self.merges;
        tally.block_strategies = self.block_strategies;
        self.touched.sort_unstable();
        let with_blocks = !self.blocks.is_empty();
        for slot in self.touched.drain(..) {
            let s = slot as usize;
            tally.entries.push((slot, self.sums[s], self.counts[s]));
            self.sums[s] = 0.0;
            self.counts[s] = 0;
            if with_blocks {
                let block = &mut self.blocks[BLOCKS * s..BLOCKS * (s + 1)];
                tally.blocks.push([block[0], block[1], block[2], block[3]]);
                block.fill(0.0);
            }
        }
        self.strategies = [0.0; PathStrategy::COUNT];
        self.merges = [0; 3];
        self.block_strategies = [[0.0; PathStrategy::COUNT]; BLOCKS];
        tally.radii.resize_with(self.radii.len(), ChunkTally::default);
        for (sub, out) in self.radii.iter_mut().zip(&mut tally.radii) {
            sub.take_into(out);
        }
    }
}

/// Everything one iteration contributes to the moments.
#[derive(Debug, Clone, PartialEq)]
pub struct IterationTally {
    /// Global iteration index s.
    pub iteration: u64,
    /// C^(m)_α,s for slot m·K + α (normalised by 1/(N_F·N_B)).
    pub cell_values: Vec<f64>,
    /// Merge events per slot.
    pub cell_counts: Vec<u64>,
    /// C_s of each per-path strategy (normalised).
    pub strategies: [f64; PathStrategy::COUNT],
    /// Merge events per plane (plane-1 hits counted once per light path).
    pub merges: [u64; 3],
    /// With noise components: each block's C^(m)_α at `block·3K + slot`, normalised as its own
    /// estimate of the pixel (by 1/((N_F/2)·(N_B/2)), so E of a block's value = E of the
    /// iteration's); empty without components or merges.
    pub block_values: Vec<f64>,
    /// Each block's per-path strategy C_s, normalised the same way.
    pub block_strategies: BlockStrategies,
    /// The iteration's tally at each smaller radius of the configuration, in its order.
    pub radii: Vec<IterationTally>,
}

impl IterationTally {
    /// Adds the chunk tallies of iteration `iteration` in chunk order and normalises.
    pub fn from_chunks<'a>(
        iteration: u64,
        cells: usize,
        norm: f64,
        chunks: impl IntoIterator<Item = &'a ChunkTally, IntoIter: Clone>,
    ) -> Self {
        let mut tally = Self {
            iteration,
            cell_values: Vec::new(),
            cell_counts: Vec::new(),
            strategies: [0.0; PathStrategy::COUNT],
            merges: [0; 3],
            block_values: Vec::new(),
            block_strategies: [[0.0; PathStrategy::COUNT]; BLOCKS],
            radii: Vec::new(),
        };
        tally.set_from_chunks(iteration, cells, norm, chunks);
        tally
    }

    /// [`IterationTally::from_chunks`] into `self`, reusing its buffers (the same values).
    pub fn set_from_chunks<'a>(
        &mut self,
        iteration: u64,
        cells: usize,
        norm: f64,
        chunks: impl IntoIterator<Item = &'a ChunkTally, IntoIter: Clone>,
    ) {
        let chunks = chunks.into_iter();
        self.set_own_from_chunks(iteration, cells, norm, chunks.clone());
        // The smaller radii (which have none of their own): the same chunks' tallies at each, in
        // the same order — a cloned iterator, so that an iteration allocates nothing once the
        // buffers have grown.
        let radii = chunks.clone().next().map_or(0, |c| c.radii.len());
        self.radii.resize_with(radii, || IterationTally::from_chunks(iteration, cells, norm, []));
        for (r, sub) in self.radii.iter_mut().enumerate() {
            sub.set_own_from_chunks(iteration, cells, norm, chunks.clone().map(move |c| &c.radii[r]));
        }
    }

    fn set_own_from_chunks<'a>(
        &mut self,
        iteration: u64,
        cells: usize,
        norm: f64,
        chunks: impl Iterator<Item = &'a ChunkTally>,
    ) {
        self.iteration = iteration;
        let (sums, cell_counts) = (&mut self.cell_values, &mut self.cell_counts);
        sums.clear();
        sums.resize(3 * cells, 0.0);
        cell_counts.clear();
        cell_counts.resize(3 * cells, 0);
        let mut strategies = [0.0; PathStrategy::COUNT];
        let mut merges = [0u64; 3];
        let blocks = &mut self.block_values;
        blocks.clear();
        let mut block_strategies = [[0.0; PathStrategy::COUNT]; BLOCKS];
        for chunk in chunks {
            for &(slot, sum, count) in &chunk.entries {
                sums[slot as usize] += sum;
                cell_counts[slot as usize] += count;
            }
            if !chunk.blocks.is_empty() && blocks.is_empty() {
                blocks.resize(BLOCKS * 3 * cells, 0.0);
            }
            for (&(slot, ..), values) in chunk.entries.iter().zip(&chunk.blocks) {
                for (b, v) in values.iter().enumerate() {
                    blocks[b * 3 * cells + slot as usize] += v;
                }
            }
            for (acc, chunk_block) in block_strategies.iter_mut().zip(&chunk.block_strategies) {
                for (a, v) in acc.iter_mut().zip(chunk_block) {
                    *a += v;
                }
            }
            for (acc, v) in strategies.iter_mut().zip(chunk.strategies) {
                *acc += v;
            }
            for (acc, v) in merges.iter_mut().zip(chunk.merges) {
                *acc += v;
            }
        }
        for s in sums.iter_mut() {
            *s *= norm;
        }
        self.strategies = strategies.map(|s| s * norm);
        self.merges = merges;
        // A block pairs N_F/2 light paths with N_B/2 camera paths: 4× the iteration's norm.
        for v in blocks.iter_mut() {
            *v *= 4.0 * norm;
        }
        self.block_strategies = block_strategies.map(|b| b.map(|v| v * 4.0 * norm));
    }

    /// The moment vector Y_s = (A⁽⁰⁾, A⁽¹⁾, B, H) of docs/model.md §7 in `layout`, as sparse (index,
    /// value) pairs in index order: A⁽ᵐ⁾_α = C⁽ᵐ⁾_α − C⁽²⁾_α for m = 0, 1 at index m·K + α,
    /// B = Σ_α C⁽²⁾_α at 2K, then each of the layout's stackable strategies' C_s (H_h).
    pub fn moment_vector(&self, layout: Layout) -> Vec<(usize, f64)> {
        let mut y = Vec::new();
        self.moment_vector_into(layout, &mut y);
        y
    }

    /// [`IterationTally::moment_vector`] into `y`, reusing its buffer.
    pub fn moment_vector_into(&self, layout: Layout, y: &mut Vec<(usize, f64)>) {
        y.clear();
        moment_vector_into(&self.cell_values, &self.strategies, layout, y);
    }

    /// The moment vector of block `b` (noise components), into `y`: empty when the iteration
    /// kept no blocks (no components, or no merge).
    pub fn block_moment_vector(&self, b: usize, layout: Layout, y: &mut Vec<(usize, f64)>) {
        y.clear();
        if !self.block_values.is_empty() {
            let slots = 3 * layout.cells;
            moment_vector_into(&self.block_values[b * slots..(b + 1) * slots], &self.block_strategies[b], layout, y);
        }
    }
}

/// Y = (A⁽⁰⁾, A⁽¹⁾, B, H) from per-slot values C⁽ᵐ⁾_α and per-path strategy values (see
/// [`IterationTally::moment_vector`]).
fn moment_vector_into(
    values: &[f64],
    strategies: &[f64; PathStrategy::COUNT],
    layout: Layout,
    y: &mut Vec<(usize, f64)>,
) {
    let cells = layout.cells;
    let c = |m: usize, a: usize| values[m * cells + a];
    for m in 0..2 {
        for a in 0..cells {
            let v = c(m, a) - c(2, a);
            if v != 0.0 {
                y.push((m * cells + a, v));
            }
        }
    }
    let b: f64 = (0..cells).map(|a| c(2, a)).sum();
    if b != 0.0 {
        y.push((2 * cells, b));
    }
    for (i, h) in layout.heuristics().iter().enumerate() {
        let v = strategies[h.index()];
        if v != 0.0 {
            y.push((2 * cells + 1 + i, v));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_reduce_in_order_and_normalise() {
        let cells = 2;
        let w = [1.0, 0.0, 0.0, 0.0, 0.5, 0.25, 0.125, 0.0, 0.0, 0.0];
        let mut scratch = ChunkScratch::new(cells);
        scratch.record(Technique::Plane1, 1, cells, 4.0, &w, CameraPaths::All);
        scratch.count_merge(Technique::Plane1);
        scratch.record(
            Technique::Plane3,
            0,
            cells,
            2.0,
            &[0.0, 0.0, 1.0, 1.0, 0.5, 0.75, 0.875, 1.0, 1.0, 1.0],
            CameraPaths::One(0),
        );
        scratch.count_merge(Technique::Plane3);
        let a = scratch.take();
        assert_eq!(a.entries, vec![(1, 4.0, 1), (4, 2.0, 1)], "slots sorted, counts kept");
        assert_eq!(scratch.take(), ChunkTally::default(), "take resets the scratch");
        scratch.record(
            Technique::Plane3,
            0,
            cells,
            6.0,
            &[0.0, 0.0, 1.0, 1.0, 0.5, 0.75, 0.875, 1.0, 1.0, 1.0],
            CameraPaths::One(1),
        );
        let b = scratch.take();
        let t = IterationTally::from_chunks(3, cells, 0.5, [&a, &b]);
        assert_eq!(t.cell_values, vec![0.0, 2.0, 0.0, 0.0, 4.0, 0.0]);
        assert_eq!(t.cell_counts, vec![0, 1, 0, 0, 2, 0]);
        assert_eq!(t.strategies, [2.0, 0.0, 4.0, 4.0, 3.0, 3.5, 3.75, 4.0, 4.0, 4.0]);
        assert_eq!(t.merges, [1, 0, 1]);
        // Y = (A0, A1, B): A0 = C0 − C2 = (0 − 4, 2 − 0), A1 = (0 − 4, 0), B = 4.
        assert_eq!(t.moment_vector(Layout::new(cells, 2)), vec![(0, -4.0), (1, 2.0), (2, -4.0), (4, 4.0)]);
        // Format 3 appends the stackable strategies' values: switch 4, balance 3, power 3.5, …
        let y = t.moment_vector(Layout::new(cells, 3));
        assert_eq!(&y[4..], &[(5, 4.0), (6, 3.0), (7, 3.5), (8, 3.75), (9, 4.0), (10, 4.0), (11, 4.0)]);
    }
}

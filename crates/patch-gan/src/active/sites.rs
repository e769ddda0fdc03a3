//! [`ActiveSites`]: the voxels a sparse generator computes, and each one's neighbours.

use candle_core::{DType, Device, Tensor};
use rayon::prelude::*;

use crate::error::{invalid, Result};

/// Marks a kernel tap that falls outside the active set (or the box).
pub(crate) const NO_SITE: u32 = u32::MAX;

/// The active sites of a batch of volumes `(B, C, D, H, W)` and, for a cubic odd kernel, the
/// neighbour of every site under every kernel tap.
///
/// Features on the sites are stored `(1, C, M, 1, 1)` for `M` sites (all batch items
/// together, in the order of the flattened volumes), so channel-wise layers such as BatchNorm run
/// on them unchanged and take their statistics over the active sites only. A convolution on the
/// sites (`functional::conv3d_active`) is *submanifold*: it computes outputs at the active sites
/// only and reads the inputs of inactive voxels as zero, so the active set does not grow from
/// layer to layer. That equals the dense convolution of the input masked to the set, masked
/// again.
///
/// ```
/// use candle_core::{Device, Tensor};
/// use patch_gan::ActiveSites;
/// // A 1 x 4 x 4 volume with its first row active.
/// let mut mask = vec![0f32; 16];
/// mask[..4].fill(1.0);
/// let mask = Tensor::from_vec(mask, (1, 1, 1, 4, 4), &Device::Cpu)?;
/// let sites = ActiveSites::from_mask(&mask, 3)?;
/// assert_eq!(sites.len(), 4);
/// assert_eq!(sites.fraction(), 0.25);
/// # Ok::<(), patch_gan::Error>(())
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ActiveSites {
    batch: usize,
    dims: [usize; 3],
    kernel: usize,
    /// Flattened index `b D H W + (d H + h) W + w` of each site, ascending.
    sites: Vec<u32>,
    /// Per kernel tap, the neighbours of sites `0..M` as runs (see [`Run`]).
    runs: Vec<Vec<Run>>,
}

/// Consecutive sites whose neighbours under one tap are consecutive too (or all missing):
/// sites `start .. start + len` read sites `source .. source + len`, or zeros where `source` is
/// [`NO_SITE`]. Along a row of active voxels every tap's neighbours run in step, so the
/// convolution's im2col columns are filled by slice copies, not one lookup per value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Run {
    pub start: u32,
    pub source: u32,
    pub len: u32,
}

impl Run {
    pub(crate) fn end(&self) -> usize {
        (self.start + self.len) as usize
    }
}

/// The runs of one tap's neighbour list (`M` values, [`NO_SITE`] for none), covering `0..M`.
fn runs_of(neighbours: &[u32]) -> Vec<Run> {
    let mut runs: Vec<Run> = Vec::new();
    for (j, &i) in neighbours.iter().enumerate() {
        if let Some(last) = runs.last_mut() {
            let continues = if last.source == NO_SITE {
                i == NO_SITE
            } else {
                i != NO_SITE && i == last.source + last.len
            };
            if continues {
                last.len += 1;
                continue;
            }
        }
        runs.push(Run {
            start: j as u32,
            source: i,
            len: 1,
        });
    }
    runs
}

impl ActiveSites {
    /// The sites where `mask` `(B, 1, D, H, W)` is above 0.5, for cubic kernels of `kernel` taps
    /// per axis (odd; padding `kernel / 2`, as the generators use).
    pub fn from_mask(mask: &Tensor, kernel: usize) -> Result<Self> {
        let (batch, channels, d, h, w) = mask.dims5().map_err(|_| {
            invalid(
                "active-set mask",
                format!("expected (B, 1, D, H, W), got {:?}", mask.shape()),
            )
        })?;
        if channels != 1 {
            return Err(invalid(
                "active-set mask",
                format!("expected one channel, got {:?}", mask.shape()),
            ));
        }
        let values: Vec<f32> = mask.flatten_all()?.to_dtype(DType::F32)?.to_vec1()?;
        let active: Vec<bool> = values.iter().map(|&v| v > 0.5).collect();
        Self::new(batch, [d, h, w], kernel, &active)
    }

    /// The sites where `active` (`batch` volumes of `dims` voxels, flattened) is true.
    pub fn new(batch: usize, dims: [usize; 3], kernel: usize, active: &[bool]) -> Result<Self> {
        if kernel.is_multiple_of(2) {
            return Err(invalid(
                "active-set kernel",
                format!("must be odd, got {kernel}"),
            ));
        }
        let voxels: usize = dims.iter().product();
        if active.len() != batch * voxels {
            return Err(invalid(
                "active-set mask",
                format!(
                    "{} values for {batch} volumes of {dims:?} ({} voxels)",
                    active.len(),
                    batch * voxels
                ),
            ));
        }
        if active.len() >= NO_SITE as usize {
            return Err(invalid(
                "active-set mask",
                format!("{} voxels do not fit 32-bit site indices", active.len()),
            ));
        }
        let sites: Vec<u32> = (0..active.len() as u32)
            .filter(|&i| active[i as usize])
            .collect();
        // The site index of every voxel, for the neighbour lookups.
        let mut index = vec![NO_SITE; active.len()];
        for (j, &s) in sites.iter().enumerate() {
            index[s as usize] = j as u32;
        }
        let runs = (0..kernel.pow(3))
            .into_par_iter()
            .map(|tap| runs_of(&neighbours_under(tap, &sites, &index, dims, kernel)))
            .collect();
        Ok(Self {
            batch,
            dims,
            kernel,
            sites,
            runs,
        })
    }

    /// Number of active sites `M`.
    pub fn len(&self) -> usize {
        self.sites.len()
    }

    /// Whether no voxel is active.
    pub fn is_empty(&self) -> bool {
        self.sites.is_empty()
    }

    /// Active sites over all voxels of the batch (0 for an empty batch).
    pub fn fraction(&self) -> f64 {
        let total = self.batch * self.dims.iter().product::<usize>();
        if total == 0 {
            0.0
        } else {
            self.len() as f64 / total as f64
        }
    }

    /// Volumes in the batch.
    pub fn batch(&self) -> usize {
        self.batch
    }

    /// `[D, H, W]` of each volume.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Kernel taps per axis the neighbour table is for.
    pub fn kernel(&self) -> usize {
        self.kernel
    }

    /// Kernel taps in all: `kernel^3`.
    pub(crate) fn taps(&self) -> usize {
        self.kernel.pow(3)
    }

    /// Flattened voxel index of each site, ascending.
    pub(crate) fn sites(&self) -> &[u32] {
        &self.sites
    }

    /// Errors, naming `what`, unless `volumes` is `(B, C, D, H, W)` with this set's batch and
    /// volume size.
    pub(crate) fn check_volumes(&self, what: &'static str, volumes: &Tensor) -> Result<()> {
        let fits =
            matches!(volumes.dims(), &[b, _, d, h, w] if b == self.batch && [d, h, w] == self.dims);
        if fits {
            return Ok(());
        }
        Err(invalid(
            what,
            format!(
                "{:?} do not match the active set's {} volumes of {:?} (expected (B, C, D, H, W))",
                volumes.shape(),
                self.batch,
                self.dims
            ),
        ))
    }

    /// The set as a mask `(B, 1, D, H, W)` of `dtype` on `device`: 1 at the active sites, 0
    /// elsewhere.
    ///
    /// ```
    /// use candle_core::{DType, Device};
    /// use patch_gan::ActiveSites;
    /// let sites = ActiveSites::new(1, [1, 2, 2], 3, &[true, false, false, true])?;
    /// let mask = sites.mask(DType::F32, &Device::Cpu)?;
    /// assert_eq!(mask.flatten_all()?.to_vec1::<f32>()?, [1., 0., 0., 1.]);
    /// # Ok::<(), patch_gan::Error>(())
    /// ```
    pub fn mask(&self, dtype: DType, device: &Device) -> Result<Tensor> {
        let [d, h, w] = self.dims;
        let mut values = vec![0f32; self.batch * d * h * w];
        for &site in &self.sites {
            values[site as usize] = 1.0;
        }
        let mask = Tensor::from_vec(values, (self.batch, 1, d, h, w), device)?;
        Ok(mask.to_dtype(dtype)?)
    }

    /// The runs of tap `t`'s neighbours, covering sites `0..M` in order.
    pub(crate) fn runs(&self, tap: usize) -> &[Run] {
        &self.runs[tap]
    }
}

/// For tap `t = (td kh + th) kw + tw` of a cubic kernel (padding `kernel / 2`), the site at
/// offset `(td, th, tw) - kernel / 2` from each site, or [`NO_SITE`] where that voxel is
/// inactive or outside the box. Taps `t` and `taps - 1 - t` are opposite offsets, so the
/// neighbours are symmetric: site `i` is under tap `t` of `j` exactly when `j` is under tap
/// `taps - 1 - t` of `i` (what lets the input gradient run as a convolution on the same sites).
fn neighbours_under(
    tap: usize,
    sites: &[u32],
    index: &[u32],
    dims: [usize; 3],
    kernel: usize,
) -> Vec<u32> {
    let [d, h, w] = dims;
    let voxels = d * h * w;
    let radius = (kernel / 2) as isize;
    let offset = [
        tap / (kernel * kernel),
        (tap / kernel) % kernel,
        tap % kernel,
    ]
    .map(|t| t as isize - radius);
    sites
        .iter()
        .map(|&site| {
            let site = site as usize;
            let (item, v) = (site / voxels, site % voxels);
            let at = [v / (h * w), (v / w) % h, v % w];
            let moved = [0, 1, 2].map(|a| at[a] as isize + offset[a]);
            if moved
                .iter()
                .zip(dims)
                .all(|(&p, n)| (0..n as isize).contains(&p))
            {
                let [md, mh, mw] = moved.map(|p| p as usize);
                index[item * voxels + (md * h + mh) * w + mw]
            } else {
                NO_SITE
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The neighbour of every site, from the runs.
    fn expand(runs: &[Run]) -> Vec<u32> {
        let mut all = Vec::new();
        for (k, run) in runs.iter().enumerate() {
            assert_eq!(all.len(), run.start as usize, "run {k} does not follow on");
            assert!(run.len > 0);
            all.extend((0..run.len).map(|o| {
                if run.source == NO_SITE {
                    NO_SITE
                } else {
                    run.source + o
                }
            }));
        }
        all
    }

    #[test]
    fn neighbours_are_the_offset_sites_and_symmetric() {
        // A 3 x 3 x 3 box, two volumes, every other voxel active.
        let active: Vec<bool> = (0..54).map(|i| i % 2 == 0).collect();
        let sites = ActiveSites::new(2, [3, 3, 3], 3, &active).unwrap();
        assert_eq!(sites.len(), 27);
        for tap in 0..27 {
            let (row, opposite) = (expand(sites.runs(tap)), expand(sites.runs(26 - tap)));
            for (j, (&site, &under)) in sites.sites().iter().zip(&row).enumerate() {
                let v = site as usize;
                let (item, p) = (v / 27, v % 27);
                let at = [p / 9, (p / 3) % 3, p % 3];
                let off = [tap / 9, (tap / 3) % 3, tap % 3];
                let moved = [0, 1, 2].map(|a| at[a] as isize + off[a] as isize - 1);
                let inside = moved.iter().all(|&m| (0..3).contains(&m));
                let expected = inside.then(|| {
                    let q = (moved[0] * 9 + moved[1] * 3 + moved[2]) as usize + item * 27;
                    active[q].then(|| sites.sites().binary_search(&(q as u32)).unwrap())
                });
                match expected.flatten() {
                    Some(i) => {
                        assert_eq!(under as usize, i, "tap {tap} site {j}");
                        assert_eq!(opposite[i] as usize, j, "symmetry, tap {tap} site {j}");
                    }
                    None => assert_eq!(under, NO_SITE, "tap {tap} site {j}"),
                }
            }
        }
    }

    #[test]
    fn bad_masks_are_refused_with_the_shapes() {
        let err = ActiveSites::new(1, [2, 2, 2], 3, &[true; 7]).unwrap_err();
        assert!(
            err.to_string()
                .contains("7 values for 1 volumes of [2, 2, 2]"),
            "{err}"
        );
        let err = ActiveSites::new(1, [2, 2, 2], 2, &[true; 8]).unwrap_err();
        assert!(err.to_string().contains("odd"), "{err}");
        let two = Tensor::zeros((1, 2, 2, 2, 2), DType::F32, &candle_core::Device::Cpu).unwrap();
        let err = ActiveSites::from_mask(&two, 3).unwrap_err();
        assert!(err.to_string().contains("one channel"), "{err}");
    }
}

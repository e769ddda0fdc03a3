//! The shape of one batched dense 3D convolution, shared by the im2col and Winograd kernels.

/// Shape of one batched 3D convolution (a 2D one is a 3D one of depth 1 with a kernel one tap
/// deep): input `(batch, c_in, D, H, W)`, kernel `(c_out, c_in, kd, kh, kw)`, output
/// `(batch, c_out, D_out, H_out, W_out)`, all contiguous and row-major.
///
/// The kernels take any value of it, but run only those [`Geometry::is_valid`] accepts (the
/// others panic), on slices of the lengths [`Geometry::input_len`], [`Geometry::kernel_len`]
/// and [`Geometry::output_len`] give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Geometry {
    /// Batch items `N`.
    pub batch: usize,
    /// Input channels.
    pub c_in: usize,
    /// Output channels.
    pub c_out: usize,
    /// Input `[D, H, W]`.
    pub input: [usize; 3],
    /// Kernel taps `[kd, kh, kw]`.
    pub kernel: [usize; 3],
    /// Zeros before and after each of `[D, H, W]`.
    pub padding: [usize; 3],
    /// Step between outputs along every axis, at least 1.
    pub stride: usize,
}

impl Geometry {
    /// Output `[D, H, W]`: `(n + 2 padding - k) / stride + 1` per axis. Meaningful for a valid
    /// geometry only ([`Geometry::is_valid`]); for another it may panic.
    pub fn output(&self) -> [usize; 3] {
        [0, 1, 2].map(|a| (self.input[a] + 2 * self.padding[a] - self.kernel[a]) / self.stride + 1)
    }

    /// The transposed convolution as a forward one, whose output is this one's input: channels
    /// swapped, padding `k - 1 - p`. Exists for stride 1 and padding below the kernel on every
    /// axis (a larger padding or a stride has no such padding).
    pub fn transposed(&self) -> Option<Geometry> {
        (self.stride == 1 && (0..3).all(|a| self.padding[a] < self.kernel[a])).then(|| Geometry {
            batch: self.batch,
            c_in: self.c_out,
            c_out: self.c_in,
            input: self.output(),
            kernel: self.kernel,
            padding: [0, 1, 2].map(|a| self.kernel[a] - 1 - self.padding[a]),
            stride: 1,
        })
    }

    /// Whether the kernels run this geometry: at least one channel each way and one tap per
    /// axis, a stride of at least 1, an input at least as large as the kernel on every axis
    /// once padded, and element counts of the input, the kernel, the output and the im2col
    /// scratch that fit in memory (no `usize` overflow).
    pub fn is_valid(&self) -> bool {
        let axes = (0..3).all(|a| {
            let padded = self.padding[a]
                .checked_mul(2)
                .and_then(|p| p.checked_add(self.input[a]));
            self.kernel[a] >= 1 && padded.is_some_and(|n| n >= self.kernel[a])
        });
        axes && self.c_in >= 1 && self.c_out >= 1 && self.stride >= 1 && self.fits()
    }

    /// Values of the input, `batch c_in D H W`.
    pub fn input_len(&self) -> usize {
        self.batch * self.c_in * self.input.iter().product::<usize>()
    }

    /// Values of the kernel, `c_out c_in kd kh kw`.
    pub fn kernel_len(&self) -> usize {
        self.c_out * self.c_in * self.kernel.iter().product::<usize>()
    }

    /// Values of the output, `batch c_out D_out H_out W_out`.
    pub fn output_len(&self) -> usize {
        self.batch * self.c_out * self.output().iter().product::<usize>()
    }

    /// Whether every product the kernels form fits in an `isize`: they stay below channels
    /// times the larger volume (at least 1) times the taps times a margin of 512 for the
    /// kernels' scratch (Winograd's transformed tiles are at most 8 values per output, im2col's
    /// columns one per output and tap, plus a partial tile or row of overhang). For a geometry
    /// whose axes are checked.
    fn fits(&self) -> bool {
        let product = |xs: &[usize]| xs.iter().try_fold(1usize, |acc, &x| acc.checked_mul(x));
        let out = [0, 1, 2]
            .map(|a| (self.input[a] + 2 * self.padding[a] - self.kernel[a]) / self.stride + 1);
        let volumes = (product(&self.input), product(&out), product(&self.kernel));
        let (Some(in_vox), Some(out_vox), Some(taps)) = volumes else {
            return false;
        };
        let channels = self.c_in.max(self.c_out);
        let volume = in_vox.max(out_vox).max(1);
        product(&[self.batch.max(1), channels, volume, taps, 512])
            .is_some_and(|largest| largest <= isize::MAX as usize)
    }
}

/// Panics unless `g` is valid and the slices `(what, len, expected)` have the lengths it implies.
#[track_caller]
pub(crate) fn assert_valid(g: &Geometry, slices: [(&str, usize, usize); 2]) {
    assert!(g.is_valid(), "conv-kernels: invalid geometry {g:?}");
    for (what, len, expected) in slices {
        assert_eq!(
            len, expected,
            "conv-kernels: {what} of {len} values for {g:?}"
        );
    }
}

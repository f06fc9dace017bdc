//! Deterministic randomness for the built-in scenes.
//!
//! Based on: PCG-32 (O'Neill 2014, "PCG: A family of simple fast space-efficient statistically good
//! algorithms for random number generation", via `rand_pcg`) for sequential streams, the SplitMix64
//! finaliser (Steele, Lea & Flood 2014, "Fast splittable pseudorandom number generators") to hash
//! integer coordinates into seeds, and 2D gradient noise with a quintic fade (Perlin 2002, "Improving
//! noise") summed as fractional Brownian motion (Musgrave, in Ebert et al., "Texturing & Modeling").
//!
//! Only IEEE-exact float operations (+, −, ×, ÷, sqrt, floor) are used here, and trigonometry elsewhere
//! goes through `libm`, so a spec gives bit-identical geometry on every machine.

use rand_core::Rng;
use rand_pcg::Pcg32;

/// SplitMix64 finaliser: a bijective 64-bit mix.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hashes a sequence of integers (signed coordinates are passed as `i64 as u64`).
#[inline]
pub fn hash(parts: &[u64]) -> u64 {
    parts
        .iter()
        .fold(0x5851_F42D_4C95_7F2D, |h, &p| mix64(h ^ mix64(p)))
}

/// A uniform float in `[0, 1)` from the top 24 bits of a hash.
#[inline]
pub fn unit_of(h: u64) -> f32 {
    (h >> 40) as f32 * (1.0 / 16_777_216.0)
}

/// A seeded PCG-32 stream with the few draws the generators need.
pub struct Rand(Pcg32);

impl Rand {
    pub fn new(key: u64) -> Self {
        Rand(Pcg32::new(mix64(key), mix64(key ^ 0xA076_1D64_78BD_642F)))
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn unit(&mut self) -> f32 {
        (self.0.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Uniform in `[lo, hi)`.
    #[inline]
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform integer in `0..n` (`n > 0`), by Lemire's multiply-shift.
    #[inline]
    pub fn below(&mut self, n: u32) -> u32 {
        ((self.0.next_u32() as u64 * n as u64) >> 32) as u32
    }

    #[inline]
    pub fn chance(&mut self, p: f32) -> bool {
        self.unit() < p
    }

    /// A uniformly chosen element of a non-empty slice.
    #[inline]
    pub fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len() as u32) as usize]
    }
}

/// Sixteen unit gradient directions (no trigonometry needed).
const GRADIENTS: [(f32, f32); 16] = [
    (1.0, 0.0),
    (0.923_879_5, 0.382_683_43),
    (0.707_106_77, 0.707_106_77),
    (0.382_683_43, 0.923_879_5),
    (0.0, 1.0),
    (-0.382_683_43, 0.923_879_5),
    (-0.707_106_77, 0.707_106_77),
    (-0.923_879_5, 0.382_683_43),
    (-1.0, 0.0),
    (-0.923_879_5, -0.382_683_43),
    (-0.707_106_77, -0.707_106_77),
    (-0.382_683_43, -0.923_879_5),
    (0.0, -1.0),
    (0.382_683_43, -0.923_879_5),
    (0.707_106_77, -0.707_106_77),
    (0.923_879_5, -0.382_683_43),
];

/// Seeded 2D gradient noise and its fBm sum.
#[derive(Clone, Copy, Debug)]
pub struct Noise {
    seed: u64,
}

impl Noise {
    pub fn new(seed: u64) -> Self {
        Noise { seed }
    }

    #[inline]
    fn grad(&self, ix: i64, iz: i64, dx: f32, dz: f32) -> f32 {
        let g = GRADIENTS[(hash(&[self.seed, ix as u64, iz as u64]) & 15) as usize];
        g.0 * dx + g.1 * dz
    }

    /// Gradient noise at `(x, z)` in lattice units, roughly in `[-1, 1]`; zero on lattice points.
    pub fn at(&self, x: f32, z: f32) -> f32 {
        let fx = x.floor();
        let fz = z.floor();
        let (ix, iz) = (fx as i64, fz as i64);
        let (dx, dz) = (x - fx, z - fz);
        // Quintic fade 6t^5 - 15t^4 + 10t^3 (Perlin 2002, "Improving noise", sec. 4).
        let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (u, v) = (fade(dx), fade(dz));
        let n00 = self.grad(ix, iz, dx, dz);
        let n10 = self.grad(ix + 1, iz, dx - 1.0, dz);
        let n01 = self.grad(ix, iz + 1, dx, dz - 1.0);
        let n11 = self.grad(ix + 1, iz + 1, dx - 1.0, dz - 1.0);
        let a = n00 + u * (n10 - n00);
        let b = n01 + u * (n11 - n01);
        // The 2D gradient-noise maximum is sqrt(1/2); scale to about [-1, 1].
        (a + v * (b - a)) * std::f32::consts::SQRT_2
    }

    /// fBm: `sum_k gain^k * noise(2^k p)` over `octaves`, normalised by the sum of amplitudes.
    pub fn fbm(&self, x: f32, z: f32, octaves: u32) -> f32 {
        let (mut sum, mut amp, mut norm, mut f) = (0.0, 1.0, 0.0, 1.0);
        for o in 0..octaves {
            // Offset each octave so lattice zeros do not line up at the origin.
            let off = 17.31 * o as f32;
            sum += amp * self.at(x * f + off, z * f - off);
            norm += amp;
            amp *= 0.5;
            f *= 2.0;
        }
        sum / norm
    }
}

/// Converts an sRGB colour (0..=255 per channel) to the linear RGBA8 the scene's vertex colours use
/// (IEC 61966-2-1 transfer function).
pub fn srgb(r: u8, g: u8, b: u8) -> [u8; 4] {
    let lin = |c: u8| {
        let c = c as f32 / 255.0;
        let l = if c <= 0.04045 {
            c / 12.92
        } else {
            libm::powf((c + 0.055) / 1.055, 2.4)
        };
        (l * 255.0 + 0.5) as u8
    };
    [lin(r), lin(g), lin(b), 255]
}

/// Scales a colour's RGB by `f` (saturating).
#[inline]
pub fn shade(c: [u8; 4], f: f32) -> [u8; 4] {
    let s = |v: u8| (v as f32 * f + 0.5).clamp(0.0, 255.0) as u8;
    [s(c[0]), s(c[1]), s(c[2]), c[3]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_draws_stay_in_range_and_are_reproducible() {
        let mut a = Rand::new(7);
        let mut b = Rand::new(7);
        for _ in 0..1000 {
            let x = a.unit();
            assert!((0.0..1.0).contains(&x));
            assert_eq!(x.to_bits(), b.unit().to_bits());
            assert!(a.below(5) < 5);
            b.below(5);
        }
    }

    #[test]
    fn noise_is_bounded_and_zero_on_lattice() {
        let n = Noise::new(3);
        assert_eq!(n.at(4.0, -2.0), 0.0);
        for i in 0..2000 {
            let v = n.at(i as f32 * 0.137, i as f32 * -0.071);
            assert!(v.abs() <= 1.01, "{v}");
        }
    }

    #[test]
    fn srgb_endpoints() {
        assert_eq!(srgb(0, 255, 188), [0, 255, 128, 255]);
    }
}

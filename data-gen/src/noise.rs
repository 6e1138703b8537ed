//! Reproducible additive Gaussian noise.

use mdtf_volume::Volume;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// Adds zero-mean Gaussian noise of standard deviation `std` (value units) to
/// every sample, from a ChaCha8 stream seeded with `seed`, in x-fastest order:
/// the same seed gives the same noise on every machine and thread count.
/// A non-positive or non-finite `std` leaves the volume unchanged.
pub fn add_gaussian_noise(volume: &mut Volume, std: f64, seed: u64) {
    let Ok(normal) = Normal::new(0.0f64, std) else {
        return;
    };
    if std <= 0.0 {
        return;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for v in volume.data.iter_mut() {
        *v = (*v as f64 + normal.sample(&mut rng)) as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mdtf_volume::Geometry;

    #[test]
    fn noise_has_the_requested_moments_and_is_reproducible() {
        let mut a = Volume::zeros(Geometry::new([40, 40, 40], [1.0; 3]));
        let mut b = a.clone();
        add_gaussian_noise(&mut a, 20.0, 7);
        add_gaussian_noise(&mut b, 20.0, 7);
        assert_eq!(a, b);
        let n = a.data.len() as f64;
        let mean = a.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = a.data.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
        assert!(mean.abs() < 0.2, "{mean}");
        assert!((var.sqrt() - 20.0).abs() < 0.2, "{}", var.sqrt());
    }
}

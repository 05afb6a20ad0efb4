//! Normalised cross-correlation: patches made zero-mean and unit-norm, so that the correlation
//! of two is their dot product, in [-1, 1], blind to brightness and contrast.

/// A patch made zero-mean and unit-norm; `None` when it is flat (its spread under a thousandth
/// of a grey level per pixel).
pub fn zero_mean_unit(mut v: Vec<f32>) -> Option<Vec<f32>> {
    let mean = v.iter().sum::<f32>() / v.len() as f32;
    v.iter_mut().for_each(|a| *a -= mean);
    let norm = v.iter().map(|a| a * a).sum::<f32>().sqrt();
    if norm < 1e-3 * v.len() as f32 {
        return None;
    }
    v.iter_mut().for_each(|a| *a /= norm);
    Some(v)
}

/// Values summed side by side in one vector register by [`dot`].
pub const LANES: usize = 8;

/// `a · b` in [`LANES`] lanes (the compiler keeps them in one vector register).
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut lanes = [0.0f32; LANES];
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..LANES {
            lanes[k] += x[k] * y[k];
        }
    }
    lanes.iter().sum::<f32>() + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_patch_correlates_with_itself_brighter_and_not_with_a_flat_one() {
        let a: Vec<f32> = (0..25).map(|i| (i * 7 % 11) as f32).collect();
        let brighter: Vec<f32> = a.iter().map(|v| 2.0 * v + 30.0).collect();
        let (a, b) = (
            zero_mean_unit(a).unwrap(),
            zero_mean_unit(brighter).unwrap(),
        );
        assert!((dot(&a, &b) - 1.0).abs() < 1e-5);
        assert!(zero_mean_unit(vec![3.0; 25]).is_none());
    }
}

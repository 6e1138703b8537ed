//! Sample arrays a pass hands back when it is done with a slab's channels,
//! for the next slab's. A slab's channels at 1024^2 planes are arrays of
//! tens of MiB, which the allocator maps fresh for every slab and unmaps
//! after it; writing fresh memory page-faults on every 4 KiB, which costs
//! the kernel about as much time as deriving the samples. The pool keeps
//! what it is given until the pass asks again, so a pass's memory stays
//! what its budget counts (two slabs' channels) and is mapped once.

use mdtf_volume::Volume;

/// Spare sample arrays of a pass (see the module docs).
#[derive(Default)]
pub struct SamplePool(Vec<Vec<f32>>);

/// Arrays a pool keeps at most: two slabs' channels of the widest pass
/// (the pack's reads hold about seven); any more are freed.
const KEPT: usize = 16;

impl SamplePool {
    /// An array of `len` samples, in spare memory when the pool holds an
    /// array with room for them (the smallest such), else fresh (zeros).
    /// Its samples are arbitrary: the caller overwrites every one.
    pub fn take(&mut self, len: usize) -> Vec<f32> {
        let fitting = self.0.iter().enumerate().filter(|(_, b)| b.capacity() >= len).min_by_key(|(_, b)| b.capacity());
        match fitting.map(|(i, _)| i) {
            Some(i) => {
                let mut samples = self.0.swap_remove(i);
                samples.resize(len, 0.0);
                samples
            }
            None => vec![0.0; len],
        }
    }

    /// Hands back `samples` for a later [`SamplePool::take`].
    pub fn give(&mut self, samples: Vec<f32>) {
        if self.0.len() < KEPT && samples.capacity() > 0 {
            self.0.push(samples);
        }
    }

    /// Hands back the memory of `volumes`.
    pub fn give_volumes(&mut self, volumes: impl IntoIterator<Item = Volume>) {
        for v in volumes {
            self.give(v.data.into_raw_vec_and_offset().0);
        }
    }

    /// Frees every spare array (between passes, whose slabs differ in size).
    pub fn clear(&mut self) {
        self.0.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_array_handed_back_is_taken_again_by_the_next_request_it_holds() {
        let mut pool = SamplePool::default();
        let mut a = pool.take(1000);
        assert_eq!(a.len(), 1000);
        a.iter_mut().for_each(|s| *s = 7.0);
        let at = a.as_ptr();
        pool.give(a);
        pool.give(Vec::with_capacity(10_000));
        // the smallest array with room: the first, shortened in place
        let b = pool.take(600);
        assert_eq!((b.len(), b.as_ptr()), (600, at));
        // too long for what is left but the larger one
        let c = pool.take(5000);
        assert!(c.len() == 5000 && c.capacity() >= 10_000);
        // nothing spare: fresh zeros
        assert_eq!(pool.take(3), [0.0; 3]);
        pool.give(b);
        pool.clear();
        assert!(pool.0.is_empty());
        for _ in 0..KEPT + 4 {
            pool.give(vec![1.0; 4]);
        }
        assert_eq!(pool.0.len(), KEPT, "at most KEPT arrays are kept");
    }
}

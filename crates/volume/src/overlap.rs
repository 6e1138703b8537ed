//! A loop over the blocks of a streamed pass with the writing of each
//! block's outputs overlapped with the making of the next: the writes
//! (copies into the page cache, on one thread) no longer leave the pool's
//! other lanes idle.

/// Makes blocks 0..`n` in order with `make(k, spent)`, handing each to
/// `take` (in the same order) while the next is made, on the pool's other
/// lanes; `start(k)` is called before block k is made (the progress).
/// `take` gives back what it is done with (or None), and the block after
/// next is made with it as `spent`, in its memory: fresh memory of a large
/// block page-faults on every page, at a cost like the making's. At most
/// two blocks are alive at once: the one taken and the one made. The first
/// error stops the loop. The whole loop is one task of the pool, so every
/// block is made on the same thread and its memory comes from and goes back
/// to one heap (made on any of the pool's threads, each would keep a heap of
/// freed blocks of its own, and the process would hold about twice its
/// blocks' memory).
pub fn overlapped<T: Send, E: Send>(
    n: usize,
    start: &mut (dyn FnMut(usize) -> Result<(), E> + Send),
    make: &mut (dyn FnMut(usize, Option<T>) -> Result<T, E> + Send),
    take: &mut (dyn FnMut(T) -> Result<Option<T>, E> + Send),
) -> Result<(), E> {
    rayon::scope(|_| {
        let (mut pending, mut spent): (Option<T>, Option<T>) = (None, None);
        for k in 0..n {
            start(k)?;
            let (last, reuse) = (pending.take(), spent.take());
            // `make` runs on this thread; the take is stolen by an idle lane
            let (made, taken) = rayon::join(|| make(k, reuse), || last.map_or(Ok(None), &mut *take));
            spent = taken?;
            pending = Some(made?);
        }
        pending.map_or(Ok(None), &mut *take).map(drop)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_block_is_taken_once_in_order_and_the_first_error_stops_the_loop() {
        let mut taken = Vec::new();
        let mut started = Vec::new();
        let mut start = |k| {
            started.push(k);
            Ok(())
        };
        let mut reused = Vec::new();
        let mut make = |k, spent: Option<usize>| {
            reused.push(spent);
            Ok(k * 10)
        };
        overlapped::<_, String>(5, &mut start, &mut make, &mut |t| {
            taken.push(t);
            Ok(Some(t))
        })
        .unwrap();
        assert_eq!(taken, vec![0, 10, 20, 30, 40]);
        assert_eq!(started, vec![0, 1, 2, 3, 4]);
        // block k is made with what the take of block k - 2 gave back
        assert_eq!(reused, vec![None, None, Some(0), Some(10), Some(20)]);
        let mut made = Vec::new();
        let e = overlapped(
            5,
            &mut |_| Ok(()),
            &mut |k, _| {
                made.push(k);
                if k == 2 { Err("block 2".to_string()) } else { Ok(k) }
            },
            &mut |_| Ok(None),
        );
        assert_eq!(e, Err("block 2".to_string()));
        assert_eq!(made, vec![0, 1, 2]);
        // a failed take stops the making within a block or two
        let mut made = 0;
        let e = overlapped(
            50,
            &mut |_| Ok(()),
            &mut |k, _| {
                made += 1;
                Ok(k)
            },
            &mut |t| if t == 1 { Err("write 1".to_string()) } else { Ok(None) },
        );
        assert_eq!(e, Err("write 1".to_string()));
        assert_eq!(made, 3, "block 1 is taken while block 2 is made");
        // every block is made on one thread
        let mut threads = std::collections::HashSet::new();
        let mut record = |_, _| {
            threads.insert(std::thread::current().id());
            Ok::<_, String>(())
        };
        overlapped(20, &mut |_| Ok(()), &mut record, &mut |_| Ok(None)).unwrap();
        assert_eq!(threads.len(), 1);
    }
}

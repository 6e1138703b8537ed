//! A loop over the blocks of a streamed pass with the writing of each
//! block's outputs overlapped with the making of the next: the writes
//! (copies into the page cache, on one thread) no longer leave the pool's
//! other lanes idle.

/// Makes blocks 0..`n` in order with `make(k)`, handing each to `take` (in
/// the same order) while the next is made, on the pool's other lanes;
/// `start(k)` is called on the calling thread before block k is made (the
/// progress). At most two blocks are alive at once: the one taken and the
/// one made. The first error of any stops the loop.
pub fn overlapped<T: Send, E: Send>(
    n: usize,
    start: &mut dyn FnMut(usize) -> Result<(), E>,
    make: &mut (dyn FnMut(usize) -> Result<T, E> + Send),
    take: &mut (dyn FnMut(T) -> Result<(), E> + Send),
) -> Result<(), E> {
    let mut pending: Option<T> = None;
    for k in 0..n {
        start(k)?;
        let last = pending.take();
        // the take is stolen by an idle lane while `make` runs here (rayon's join)
        let (made, taken) = rayon::join(|| make(k), || last.map_or(Ok(()), &mut *take));
        taken?;
        pending = Some(made?);
    }
    pending.map_or(Ok(()), take)
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
        overlapped::<_, String>(5, &mut start, &mut |k| Ok(k * 10), &mut |t| {
            taken.push(t);
            Ok(())
        })
        .unwrap();
        assert_eq!(taken, vec![0, 10, 20, 30, 40]);
        assert_eq!(started, vec![0, 1, 2, 3, 4]);
        let mut made = Vec::new();
        let e = overlapped(
            5,
            &mut |_| Ok(()),
            &mut |k| {
                made.push(k);
                if k == 2 { Err("block 2".to_string()) } else { Ok(k) }
            },
            &mut |_| Ok(()),
        );
        assert!(e.is_err() && made == vec![0, 1, 2], "{made:?}");
        let e =
            overlapped(5, &mut |_| Ok(()), &mut Ok, &mut |t| if t == 1 { Err("write 1".to_string()) } else { Ok(()) });
        assert_eq!(e, Err("write 1".to_string()));
    }
}

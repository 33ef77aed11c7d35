//! Mailboxing (Amanatides & Woo 1987): a space partition holds a triangle in every cell it
//! overlaps, so a ray meets it again in the next cells; a few recently tested triangle ids,
//! kept per ray, skip those repeats. A skipped test could not have changed the answer: it ran
//! with a `tmax` no smaller than today's.

/// The last [`Mailbox::SIZE`] triangles a ray tested, as a ring.
pub(super) struct Mailbox {
    ids: [u32; Mailbox::SIZE],
    next: usize,
}

impl Mailbox {
    /// Ids remembered.
    pub(super) const SIZE: usize = 8;

    /// An empty mailbox.
    #[inline(always)]
    pub(super) fn new() -> Self {
        Self {
            ids: [u32::MAX; Self::SIZE],
            next: 0,
        }
    }

    /// True when `id` was tested recently; otherwise remembers it and returns false.
    #[inline(always)]
    pub(super) fn seen(&mut self, id: u32) -> bool {
        if self.ids.contains(&id) {
            return true;
        }
        self.ids[self.next] = id;
        self.next = (self.next + 1) % Self::SIZE;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remembers_the_last_ids() {
        let mut m = Mailbox::new();
        assert!(!m.seen(3));
        assert!(m.seen(3));
        for i in 10..10 + Mailbox::SIZE as u32 {
            assert!(!m.seen(i));
        }
        assert!(!m.seen(3), "evicted after SIZE others");
    }
}

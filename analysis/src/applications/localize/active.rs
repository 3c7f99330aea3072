//! Which landmarks' persistent errors the filter carries: at most
//! [`ACTIVE`] at once, the most recently sighted.
//!
//! Each carried error is correlated with the pose and with every other one,
//! so a sighting's update costs the square of how many are carried: with a
//! map of 150 landmarks all of them made a 4.5 min log take 146 s. A landmark
//! not sighted for the longest time has the error that has decayed most
//! toward its prior (by exp(-dt / memory)); letting it go restarts it from that
//! prior, uncorrelated, when it is sighted again. A map of up to [`ACTIVE`]
//! landmarks is carried whole, exactly as before.

/// The most landmarks whose persistent errors are carried at once: more than
/// a camera sights within an error's memory in a room of barcoded landmarks
/// (the MRCLAM maps have 15), and few enough that an update stays cheap.
pub const ACTIVE: usize = 24;

/// Landmarks mapped to the slots that hold their errors, least recently
/// sighted first to go.
#[derive(Debug, Clone)]
pub struct Slots {
    /// The slot of each landmark, if it has one.
    slot: Vec<Option<usize>>,
    /// The landmark in each slot, and when it was last sighted.
    owner: Vec<Option<(usize, f64)>>,
}

/// Where a sighted landmark's error is: in the slot it had, or in a slot it
/// now takes, which held nothing or another landmark's error (to be reset).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Taken {
    Kept(usize),
    Fresh(usize),
    Evicted(usize),
}

impl Slots {
    /// Slots for `landmarks` landmarks, `capacity` of them carried at once.
    pub fn new(landmarks: usize, capacity: usize) -> Slots {
        Slots {
            slot: vec![None; landmarks],
            owner: vec![None; capacity.min(landmarks)],
        }
    }

    /// The slot of landmark `l`, sighted at `t`.
    pub fn take(&mut self, l: usize, t: f64) -> Taken {
        if let Some(s) = self.slot[l] {
            self.owner[s] = Some((l, t));
            return Taken::Kept(s);
        }
        let (s, taken) = match self.owner.iter().position(Option::is_none) {
            Some(s) => (s, Taken::Fresh(s)),
            None => {
                // the least recently sighted (the first such: deterministic)
                let s = (0..self.owner.len())
                    .min_by(|&a, &b| {
                        let at = |k: usize| self.owner[k].map_or(f64::NEG_INFINITY, |o| o.1);
                        at(a).total_cmp(&at(b))
                    })
                    .expect("a full table has slots");
                if let Some((old, _)) = self.owner[s] {
                    self.slot[old] = None;
                }
                (s, Taken::Evicted(s))
            }
        };
        self.slot[l] = Some(s);
        self.owner[s] = Some((l, t));
        taken
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_least_recently_sighted_landmark_gives_up_its_slot() {
        let mut s = Slots::new(4, 2);
        assert_eq!(s.take(0, 0.0), Taken::Fresh(0));
        assert_eq!(s.take(1, 1.0), Taken::Fresh(1));
        assert_eq!(s.take(0, 2.0), Taken::Kept(0));
        // landmark 1 was sighted longest ago
        assert_eq!(s.take(2, 3.0), Taken::Evicted(1));
        assert_eq!(s.take(1, 4.0), Taken::Evicted(0));
        assert_eq!(s.take(2, 5.0), Taken::Kept(1));
    }

    #[test]
    fn a_small_map_is_carried_whole() {
        let mut s = Slots::new(3, ACTIVE);
        for (k, l) in [0, 1, 2, 1, 0, 2].into_iter().enumerate() {
            assert!(!matches!(s.take(l, k as f64), Taken::Evicted(_)));
        }
    }
}

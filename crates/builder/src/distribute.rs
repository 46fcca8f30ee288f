//! The distributed build's plan and messages (ATP section 5.3, parallel construction).
//!
//! Which rank simplifies which diamond: each level's diamonds in Morton order of their
//! first tetrahedron's centre, cut into `size` runs of about equal tetrahedron counts
//! ([`Plan`]). Consecutive levels cut the same space curve, so most of a diamond's
//! children were made on its own rank and only the patches along the cuts travel.
//!
//! What travels at the end of a level ([`NodeMessage`]): a new node's record and its
//! working patch (and re-cut texels) to the rank that owns its parent's diamond; a
//! finished node's record and encoded patch to rank 0, which writes the model. Every
//! byte of the output comes from the same per-diamond computation whichever rank ran it,
//! so the model is the single process's, byte for byte.
//!
//! Every message starts with a status byte ([`frame`]): a rank that failed sends its
//! error's text instead of its payload, and every rank stops with the failure of the
//! lowest failing rank ([`settle`]).

use crate::partition::{parent_id, TetId};
use crate::peers::{PeerError, Peers};
use crate::BuildError;
use rustc_hash::FxHashMap;
use tessera_tetra::Tet;

/// Who simplifies each diamond, and so who needs each node next.
pub(crate) struct Plan {
    size: usize,
    /// Rank of the diamond of every internal tetrahedron (empty for a single process).
    owner: FxHashMap<TetId, u32>,
}

impl Plan {
    /// `levels[l]`: the diamonds of level `l`, each a list of its tetrahedra.
    pub(crate) fn new(levels: &[Vec<Vec<Tet>>], size: usize) -> Plan {
        let mut owner = FxHashMap::default();
        if size > 1 {
            for diamonds in levels {
                let mut order: Vec<(u64, u8, u64, usize)> = diamonds
                    .iter()
                    .enumerate()
                    .map(|(i, d)| (d[0].morton(), d[0].root, d[0].path, i))
                    .collect();
                order.sort_unstable();
                let total: usize = diamonds.iter().map(Vec::len).sum();
                let mut before = 0usize;
                for &(_, _, _, i) in &order {
                    // The rank whose share of the level's tetrahedra this one starts in.
                    let rank = (before * size / total.max(1)).min(size - 1) as u32;
                    before += diamonds[i].len();
                    for t in &diamonds[i] {
                        owner.insert((t.root, t.level, t.path), rank);
                    }
                }
            }
        }
        Plan { size, owner }
    }

    /// The rank that simplifies the diamond of the internal tetrahedron `id`.
    pub(crate) fn owner(&self, id: TetId) -> usize {
        if self.size == 1 {
            return 0;
        }
        self.owner.get(&id).map_or(0, |&r| r as usize)
    }

    /// The rank that needs node `id` next: its parent's diamond's, or rank 0 for a root
    /// (roots are encoded where the model is written).
    pub(crate) fn next_owner(&self, id: TetId) -> usize {
        parent_id(id).map_or(0, |p| self.owner(p))
    }
}

/// Little-endian writer of the messages' fields.
#[derive(Default)]
pub(crate) struct Wire {
    pub(crate) bytes: Vec<u8>,
}

impl Wire {
    pub(crate) fn u8(&mut self, v: u8) {
        self.bytes.push(v);
    }
    pub(crate) fn u16(&mut self, v: u16) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn u32(&mut self, v: u32) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn u64(&mut self, v: u64) {
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }
    /// Bit-exact: the receiver gets the very same `f64`.
    pub(crate) fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    pub(crate) fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }
    pub(crate) fn blob(&mut self, b: Option<&[u8]>) {
        match b {
            None => self.u8(0),
            Some(b) => {
                self.u8(1);
                self.u64(b.len() as u64);
                self.bytes.extend_from_slice(b);
            }
        }
    }
    pub(crate) fn str(&mut self, s: &str) {
        self.blob(Some(s.as_bytes()));
    }
}

/// Reader of what [`Wire`] wrote; every read is checked (a short or corrupt message is
/// an internal error naming its sender, never a panic).
pub(crate) struct Unwire<'a> {
    bytes: &'a [u8],
    from: usize,
}

impl<'a> Unwire<'a> {
    pub(crate) fn new(bytes: &'a [u8], from: usize) -> Unwire<'a> {
        Unwire { bytes, from }
    }
    #[cfg(test)]
    pub(crate) fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], BuildError> {
        if self.bytes.len() < n {
            return Err(BuildError::Internal(format!(
                "a message from rank {} ends early",
                self.from
            )));
        }
        let (a, b) = self.bytes.split_at(n);
        self.bytes = b;
        Ok(a)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], BuildError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub(crate) fn u8(&mut self) -> Result<u8, BuildError> {
        Ok(self.take(1)?[0])
    }
    pub(crate) fn u16(&mut self) -> Result<u16, BuildError> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, BuildError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub(crate) fn u64(&mut self) -> Result<u64, BuildError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub(crate) fn f64(&mut self) -> Result<f64, BuildError> {
        Ok(f64::from_bits(self.u64()?))
    }
    pub(crate) fn f32(&mut self) -> Result<f32, BuildError> {
        Ok(f32::from_bits(self.u32()?))
    }
    pub(crate) fn blob(&mut self) -> Result<Option<&'a [u8]>, BuildError> {
        match self.u8()? {
            0 => Ok(None),
            1 => {
                let n = usize::try_from(self.u64()?).map_err(|_| self.corrupt())?;
                Ok(Some(self.take(n)?))
            }
            _ => Err(self.corrupt()),
        }
    }
    pub(crate) fn str(&mut self) -> Result<String, BuildError> {
        let b = self.blob()?.ok_or_else(|| self.corrupt())?;
        String::from_utf8(b.to_vec()).map_err(|_| self.corrupt())
    }
    fn corrupt(&self) -> BuildError {
        BuildError::Internal(format!("a corrupt message from rank {}", self.from))
    }
}

const OK: u8 = 0;
const FAILED: u8 = 1;

/// Prefixes each message with this rank's status: the payloads, or the error's text
/// for every rank.
fn frame(r: &Result<Vec<Vec<u8>>, BuildError>, size: usize) -> Vec<Vec<u8>> {
    match r {
        Ok(msgs) => msgs
            .iter()
            .map(|m| {
                let mut f = Vec::with_capacity(m.len() + 1);
                f.push(OK);
                f.extend_from_slice(m);
                f
            })
            .collect(),
        Err(e) => {
            let mut f = vec![FAILED];
            f.extend_from_slice(e.to_string().as_bytes());
            vec![f; size]
        }
    }
}

/// One exchange point: sends this rank's messages (or its error) and returns what the
/// others sent, by rank, without the status bytes. When any rank failed, every rank
/// returns the failure of the lowest failing rank: this rank's own error when that is
/// it (the same error as a single process), else [`BuildError::Peer`] with its text.
/// `cancelled` is polled while waiting.
pub(crate) fn settle(
    peers: &dyn Peers,
    mine: Result<Vec<Vec<u8>>, BuildError>,
    cancelled: &dyn Fn() -> bool,
) -> Result<Vec<Vec<u8>>, BuildError> {
    let size = peers.size();
    if size == 1 {
        return mine;
    }
    if let Ok(m) = &mine {
        if m.len() != size {
            return Err(BuildError::Internal("one message per rank expected".into()));
        }
    }
    let framed = frame(&mine, size);
    let got = match peers.exchange(framed, cancelled) {
        Ok(g) => g,
        Err(PeerError::Cancelled) => return Err(BuildError::Interrupted),
        Err(PeerError::Failed(why)) => return Err(BuildError::Internal(why)),
    };
    let me = peers.rank();
    if let Some((from, text)) = got
        .iter()
        .enumerate()
        .find(|(_, m)| m.first() != Some(&OK))
        .map(|(from, m)| {
            (
                from,
                String::from_utf8_lossy(m.get(1..).unwrap_or(&[])).into_owned(),
            )
        })
    {
        return Err(match mine {
            Err(own) if from == me => own,
            _ => BuildError::Peer {
                rank: from,
                message: text,
            },
        });
    }
    mine?;
    Ok(got.into_iter().map(|mut m| m.split_off(1)).collect())
}

/// [`settle`] with nothing to send: every rank learns whether all succeeded.
pub(crate) fn agree<T>(
    peers: &dyn Peers,
    r: Result<T, BuildError>,
    cancelled: &dyn Fn() -> bool,
) -> Result<T, BuildError> {
    let size = peers.size();
    if size == 1 {
        return r;
    }
    match r {
        Ok(v) => settle(peers, Ok(vec![Vec::new(); size]), cancelled).map(|_| v),
        Err(e) => match settle(peers, Err(e), cancelled) {
            Err(e) => Err(e),
            Ok(_) => Err(BuildError::Internal(
                "an error vanished in the exchange".into(),
            )),
        },
    }
}

/// One level of one rank, for the report and `scripts/bench-mpi`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LevelStats {
    pub level: u32,
    /// Diamonds this rank simplified.
    pub diamonds: u64,
    /// Seconds simplifying them (wall clock, all threads of the rank).
    pub work_seconds: f64,
    /// Seconds packing, waiting for and unpacking the level's exchange.
    pub exchange_seconds: f64,
    /// Bytes sent to other ranks and received from them (this rank's own share is
    /// not counted).
    pub bytes_sent: u64,
    pub bytes_received: u64,
}

/// What one rank did ([`crate::BuildReport::ranks`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RankStats {
    pub rank: u32,
    /// (stage, seconds) of this rank, as [`crate::BuildReport::stage_seconds`].
    pub stage_seconds: Vec<(String, f64)>,
    pub levels: Vec<LevelStats>,
    /// Peak resident set size of the rank's process (Linux), 0 when unknown.
    pub peak_rss_bytes: u64,
}

impl RankStats {
    pub(crate) fn write(&self, w: &mut Wire) {
        w.u32(self.rank);
        w.u64(self.stage_seconds.len() as u64);
        for (name, s) in &self.stage_seconds {
            w.str(name);
            w.f64(*s);
        }
        w.u64(self.levels.len() as u64);
        for l in &self.levels {
            w.u32(l.level);
            w.u64(l.diamonds);
            w.f64(l.work_seconds);
            w.f64(l.exchange_seconds);
            w.u64(l.bytes_sent);
            w.u64(l.bytes_received);
        }
        w.u64(self.peak_rss_bytes);
    }

    pub(crate) fn read(r: &mut Unwire) -> Result<RankStats, BuildError> {
        let rank = r.u32()?;
        let n = r.u64()?;
        let mut stage_seconds = Vec::new();
        for _ in 0..n {
            stage_seconds.push((r.str()?, r.f64()?));
        }
        let n = r.u64()?;
        let mut levels = Vec::new();
        for _ in 0..n {
            levels.push(LevelStats {
                level: r.u32()?,
                diamonds: r.u64()?,
                work_seconds: r.f64()?,
                exchange_seconds: r.f64()?,
                bytes_sent: r.u64()?,
                bytes_received: r.u64()?,
            });
        }
        Ok(RankStats {
            rank,
            stage_seconds,
            levels,
            peak_rss_bytes: r.u64()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::peers::LocalPeers;

    /// A level cut for 3 ranks: every diamond has one owner, shares differ by at most
    /// one diamond's tetrahedra, and a single process owns everything.
    #[test]
    fn plan_balances_a_level() {
        let root = Tet::roots()[0];
        let mut level = vec![root];
        for _ in 0..6 {
            level = level.iter().flat_map(|t| t.children()).collect();
        }
        let diamonds: Vec<Vec<Tet>> = level.iter().map(|t| vec![*t]).collect();
        let plan = Plan::new(std::slice::from_ref(&diamonds), 3);
        let mut count = [0usize; 3];
        for d in &diamonds {
            count[plan.owner((d[0].root, d[0].level, d[0].path))] += 1;
        }
        assert_eq!(count.iter().sum::<usize>(), 64);
        assert!(count.iter().all(|&c| (21..=22).contains(&c)), "{count:?}");
        let solo = Plan::new(std::slice::from_ref(&diamonds), 1);
        assert_eq!(solo.owner((0, 6, 5)), 0);
        assert_eq!(plan.next_owner((0, 0, 0)), 0);
    }

    /// A failure on rank 1 reaches every rank as rank 1's message; rank 1 keeps its
    /// own error (so its variant, e.g. `Interrupted`, survives).
    #[test]
    fn settle_spreads_the_lowest_failure() {
        let handles: Vec<_> = LocalPeers::group(3)
            .into_iter()
            .map(|p| {
                std::thread::spawn(move || {
                    let mine = match p.rank() {
                        1 => Err(BuildError::Options("bad on one".into())),
                        2 => Err(BuildError::Interrupted),
                        _ => Ok(vec![vec![7u8]; 3]),
                    };
                    (p.rank(), settle(&p, mine, &|| false).unwrap_err())
                })
            })
            .collect();
        for h in handles {
            let (rank, e) = h.join().unwrap();
            assert_eq!(e.to_string(), "invalid option: bad on one", "rank {rank}");
            assert_eq!(matches!(e, BuildError::Options(_)), rank == 1);
        }
    }

    #[test]
    fn stats_round_trip() {
        let s = RankStats {
            rank: 2,
            stage_seconds: vec![("import".into(), 1.5)],
            levels: vec![LevelStats {
                level: 7,
                diamonds: 3,
                work_seconds: 0.25,
                exchange_seconds: 0.125,
                bytes_sent: 10,
                bytes_received: 20,
            }],
            peak_rss_bytes: 1 << 20,
        };
        let mut w = Wire::default();
        s.write(&mut w);
        let mut r = Unwire::new(&w.bytes, 2);
        assert_eq!(RankStats::read(&mut r).unwrap(), s);
        assert!(r.is_empty());
        // Cut short: an error, not a panic.
        let mut r = Unwire::new(&w.bytes[..w.bytes.len() - 3], 2);
        assert!(RankStats::read(&mut r).is_err());
    }
}

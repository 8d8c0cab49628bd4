//! Streaming node payloads: an LRU cache with a memory budget, filled by background threads,
//! so that a frame never waits on disk.
//!
//! Each frame calls [`Streamer::request`] with its cut (in priority order) and draws
//! [`Streamer::resident_cut`]: every cut node that is in memory. The tree is additive, so a
//! node that is not leaves its region drawn by its resident ancestors, more coarsely (the
//! nearest resident ancestor is drawn even when the cut does not name it). The root is loaded
//! when the streamer is created and never evicted, so every frame has something to draw; the
//! next frames refine as loads complete. Nodes of the latest cut are pinned; the others are
//! evicted least recently used first when the cache is over its budget.

use crate::format::LodTree;
use crate::record::Record;
use crate::LodError;
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub type Payload = Arc<Vec<Record>>;

struct Entry {
    data: Payload,
    last_used: u64,
}

#[derive(Default)]
struct State {
    resident: HashMap<u32, Entry>,
    bytes: u64,
    queue: VecDeque<u32>,
    in_flight: HashSet<u32>,
    pinned: HashSet<u32>,
    clock: u64,
    error: Option<String>,
    stop: bool,
    loads: u64,
    evictions: u64,
}

struct Shared {
    tree: Arc<LodTree>,
    budget: u64,
    state: Mutex<State>,
    wake: Condvar,
    idle: Condvar,
}

/// Counters for benchmarks and progress messages.
#[derive(Clone, Copy, Debug, Default)]
pub struct StreamStats {
    pub resident_nodes: usize,
    pub resident_bytes: u64,
    pub queued: usize,
    pub in_flight: usize,
    pub loads: u64,
    pub evictions: u64,
}

pub struct Streamer {
    shared: Arc<Shared>,
    parent: Vec<u32>,
    workers: Vec<JoinHandle<()>>,
}

fn lock(s: &Shared) -> MutexGuard<'_, State> {
    s.state.lock().unwrap_or_else(|e| e.into_inner())
}

impl Streamer {
    /// Loads the root, then starts `threads` loaders. `budget` is in bytes of payload.
    pub fn new(tree: Arc<LodTree>, budget: u64, threads: usize) -> Result<Streamer, LodError> {
        let root = Arc::new(tree.read_node(0)?);
        let mut parent = vec![u32::MAX; tree.nodes.len()];
        for (i, n) in tree.nodes.iter().enumerate() {
            if !n.is_leaf() {
                for c in n.children {
                    parent[c as usize] = i as u32;
                }
            }
        }
        let mut st = State {
            bytes: bytes_of(&root),
            ..Default::default()
        };
        st.resident.insert(
            0,
            Entry {
                data: root,
                last_used: 0,
            },
        );
        let shared = Arc::new(Shared {
            tree,
            budget,
            state: Mutex::new(st),
            wake: Condvar::new(),
            idle: Condvar::new(),
        });
        let mut streamer = Streamer {
            shared,
            parent,
            workers: Vec::new(),
        };
        for k in 0..threads.max(1) {
            let s = streamer.shared.clone();
            let w = std::thread::Builder::new()
                .name(format!("stipple-lod-loader-{k}"))
                .spawn(move || loader(&s))
                .map_err(|e| LodError::Invalid(format!("cannot start a loader thread: {e}")))?;
            streamer.workers.push(w);
        }
        Ok(streamer)
    }

    pub fn tree(&self) -> &LodTree {
        &self.shared.tree
    }

    /// Makes `cut` the wanted set: its missing nodes are queued in the given order (replacing
    /// the previous queue), its resident ones are marked used.
    pub fn request(&self, cut: &[u32]) {
        let mut st = lock(&self.shared);
        st.clock += 1;
        let now = st.clock;
        st.pinned = cut.iter().copied().collect();
        st.pinned.insert(0);
        st.queue.clear();
        for &id in cut {
            if let Some(e) = st.resident.get_mut(&id) {
                e.last_used = now;
            } else if !st.in_flight.contains(&id) {
                st.queue.push_back(id);
            }
        }
        drop(st);
        self.shared.wake.notify_all();
    }

    /// What to draw now for `cut`: resident nodes, and for missing ones their nearest
    /// resident ancestor (each drawn once). Also returns how many cut nodes were missing.
    pub fn resident_cut(&self, cut: &[u32]) -> (Vec<(u32, Payload)>, usize) {
        let mut st = lock(&self.shared);
        st.clock += 1;
        let now = st.clock;
        let mut seen = HashSet::new();
        let mut out = Vec::new();
        let mut missing = 0;
        for &id in cut {
            let mut n = id;
            if !st.resident.contains_key(&n) {
                missing += 1;
                while !st.resident.contains_key(&n) && n != 0 {
                    n = self.parent[n as usize];
                }
            }
            if seen.insert(n) {
                let e = st
                    .resident
                    .get_mut(&n)
                    .expect("the root is always resident");
                e.last_used = now;
                out.push((n, e.data.clone()));
            }
        }
        (out, missing)
    }

    /// Blocks until nothing is queued or loading, or `timeout` passes; returns whether idle.
    pub fn wait_idle(&self, timeout: Duration) -> bool {
        let end = Instant::now() + timeout;
        let mut st = lock(&self.shared);
        loop {
            if (st.queue.is_empty() && st.in_flight.is_empty()) || st.error.is_some() {
                return true;
            }
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            st = self
                .shared
                .idle
                .wait_timeout(st, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    /// The first load error (a corrupt payload, a read failure), if any.
    pub fn error(&self) -> Option<String> {
        lock(&self.shared).error.clone()
    }

    pub fn stats(&self) -> StreamStats {
        let st = lock(&self.shared);
        StreamStats {
            resident_nodes: st.resident.len(),
            resident_bytes: st.bytes,
            queued: st.queue.len(),
            in_flight: st.in_flight.len(),
            loads: st.loads,
            evictions: st.evictions,
        }
    }
}

impl Drop for Streamer {
    fn drop(&mut self) {
        lock(&self.shared).stop = true;
        self.shared.wake.notify_all();
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

fn bytes_of(p: &Payload) -> u64 {
    (p.len() * Record::SIZE) as u64
}

fn loader(s: &Shared) {
    loop {
        let id = {
            let mut st = lock(s);
            loop {
                if st.stop {
                    return;
                }
                if let Some(id) = st.queue.pop_front() {
                    if !st.resident.contains_key(&id) && st.in_flight.insert(id) {
                        break id;
                    }
                    continue;
                }
                s.idle.notify_all();
                st = s.wake.wait(st).unwrap_or_else(|e| e.into_inner());
            }
        };
        let r = s.tree.read_node(id);
        let mut st = lock(s);
        st.in_flight.remove(&id);
        match r {
            Ok(recs) => {
                let data = Arc::new(recs);
                st.bytes += bytes_of(&data);
                st.clock += 1;
                let now = st.clock;
                st.resident.insert(
                    id,
                    Entry {
                        data,
                        last_used: now,
                    },
                );
                st.loads += 1;
                evict(&mut st, s.budget);
            }
            Err(e) => {
                if st.error.is_none() {
                    st.error = Some(e.to_string());
                }
                st.queue.clear();
            }
        }
        if st.queue.is_empty() && st.in_flight.is_empty() {
            s.idle.notify_all();
        }
    }
}

/// Evicts least recently used, unpinned nodes (never the root) until within `budget`.
fn evict(st: &mut State, budget: u64) {
    if st.bytes <= budget {
        return;
    }
    let mut victims: Vec<(u64, u32)> = st
        .resident
        .iter()
        .filter(|(id, _)| **id != 0 && !st.pinned.contains(id))
        .map(|(id, e)| (e.last_used, *id))
        .collect();
    victims.sort_unstable();
    for (_, id) in victims {
        if st.bytes <= budget {
            break;
        }
        if let Some(e) = st.resident.remove(&id) {
            st.bytes -= bytes_of(&e.data);
            st.evictions += 1;
        }
    }
}

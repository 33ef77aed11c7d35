//! Background rebuild (Ize, Wald & Parker 2007, asynchronous BVH construction): a deforming
//! mesh's tree is rebuilt on a worker thread from a snapshot of its positions while the frame
//! loop keeps refitting the old tree; at the frame the build is due the new tree is swapped in
//! and refitted to the current positions. The due frame is fixed when the build starts (from
//! the build's price and the frame's trace cost), and the engine waits there if the build is
//! late, so that the schedule is the same on every run whatever the machine's load.
//!
//! One worker per engine, one build at a time. The worker builds sequentially (in a rayon pool
//! of one thread, `parallel_threshold` off): it runs beside the frame's rayon pool instead of
//! queueing its tasks among the frame's tracing tasks. With [`WorkerPriority::Idle`] it runs in
//! the scheduler's idle class (Linux `SCHED_IDLE`), on cycles no thread of normal priority
//! wants: the frame loop's serial steps, its threads' idle spins and the gaps between frames,
//! so that the frames beside a build are not slowed by a third thread on their cores; if it is
//! late at the due frame, the engine's wait frees a core for it (unless other processes take
//! it). Either way its run-queue wait is not counted as the machine's load.

use crate::bvh::{BuildParams, BuildWorkspace, MeshBvh, MeshBvh8};
use crate::engine::{MeshId, WorkerPriority};
use glam::Vec3;
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Instant;

/// A build's input and output, moved to the worker and back (its buffers kept from one build
/// to the next).
#[derive(Default)]
pub(super) struct Job {
    pub mesh: Option<MeshId>,
    pub positions: Vec<Vec3>,
    pub indices: Vec<[u32; 3]>,
    pub tree: MeshBvh,
    /// The 8-wide tree collapsed from it, when the engine traces wide trees.
    pub wide: Option<MeshBvh8>,
    ws: BuildWorkspace,
    params: Option<BuildParams>,
    /// Collapse `wide` after the build.
    collapse: bool,
    /// The build's wall time on the worker, ms.
    pub build_ms: f64,
}

#[derive(Default)]
struct Slot {
    job: Option<Job>,
    queued: bool,
    done: bool,
    quit: bool,
}

#[derive(Default)]
struct Shared {
    slot: Mutex<Slot>,
    wake: Condvar,
}

/// The worker and the job it holds or will hold.
#[derive(Default)]
pub(super) struct Background {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
    /// The job's buffers while no build runs.
    idle: Option<Job>,
    /// The mesh whose build runs or waits to be swapped in, and the frame it is due.
    busy: Option<MeshId>,
    due: u64,
    /// The worker's scheduling class.
    priority: WorkerPriority,
    /// Bytes of the job's buffers when it was last handed to the worker.
    job_bytes: usize,
}

impl Job {
    /// Bytes held.
    fn memory_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.positions)
            + held(&self.indices)
            + self.tree.storage_bytes()
            + self.wide.as_ref().map_or(0, MeshBvh8::storage_bytes)
            + self.ws.memory_bytes()
    }
}

impl Background {
    /// Bytes of the build's buffers, kept between builds (while a build runs, as they were
    /// when it started).
    pub fn memory_bytes(&self) -> usize {
        self.idle.as_ref().map_or(self.job_bytes, Job::memory_bytes)
    }

    /// No worker yet; it will run at `priority`.
    pub fn new(priority: WorkerPriority) -> Self {
        let mut b = Self::default();
        b.priority = priority;
        b
    }

    /// Starts the worker and sizes the job's buffers for a mesh of `vertices` and `triangles`
    /// (like `tree`, and `wide` when the engine traces wide trees), so that starting a build
    /// allocates nothing. Allocates.
    pub fn reserve(
        &mut self,
        vertices: usize,
        triangles: usize,
        tree: &MeshBvh,
        wide: Option<&MeshBvh8>,
    ) {
        if self.worker.is_none() {
            let shared = Arc::clone(&self.shared);
            let idle = self.priority == WorkerPriority::Idle;
            self.worker = Some(std::thread::spawn(move || work(&shared, idle)));
        }
        let job = self.idle.get_or_insert_with(Job::default);
        job.positions
            .reserve(vertices.saturating_sub(job.positions.len()));
        job.indices
            .reserve(triangles.saturating_sub(job.indices.len()));
        job.tree.reserve_like(tree);
        if let (None, Some(w)) = (&job.wide, wide) {
            job.wide = Some(w.clone());
        }
    }

    /// Starts rebuilding `mesh` from these positions and triangles (copied), and collapsing
    /// the 8-wide tree when `wide`; false (nothing started) while another build runs.
    pub fn start(
        &mut self,
        mesh: MeshId,
        positions: &[Vec3],
        indices: &[[u32; 3]],
        params: &BuildParams,
        wide: bool,
        due: u64,
    ) -> bool {
        if self.busy.is_some() {
            return false;
        }
        if self.worker.is_none() {
            self.reserve(positions.len(), indices.len(), &MeshBvh::default(), None);
        }
        let mut job = self.idle.take().unwrap_or_default();
        if wide && job.wide.is_none() {
            job.wide = Some(MeshBvh8::default());
        }
        job.collapse = wide;
        job.mesh = Some(mesh);
        job.positions.clear();
        job.positions.extend_from_slice(positions);
        job.indices.clear();
        job.indices.extend_from_slice(indices);
        job.params = Some(BuildParams {
            parallel_threshold: usize::MAX,
            ..*params
        });
        self.job_bytes = job.memory_bytes();
        let mut slot = self
            .shared
            .slot
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        slot.job = Some(job);
        slot.queued = true;
        slot.done = false;
        drop(slot);
        self.shared.wake.notify_one();
        self.busy = Some(mesh);
        self.due = due;
        true
    }

    /// A build of `mesh` runs or waits to be swapped in.
    pub fn running(&self, mesh: MeshId) -> bool {
        self.busy == Some(mesh)
    }

    /// The build of `mesh` when it is due at `frame` (waiting for it if it is late); its
    /// buffers come back with the next [`Background::recycle`].
    pub fn take_due(&mut self, mesh: MeshId, frame: u64) -> Option<Job> {
        if self.busy != Some(mesh) || frame < self.due {
            return None;
        }
        let job = self.wait();
        self.busy = None;
        job
    }

    /// Waits for the running build and takes it.
    fn wait(&mut self) -> Option<Job> {
        let mut slot = self
            .shared
            .slot
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        while !slot.done {
            slot = self
                .shared
                .wake
                .wait(slot)
                .unwrap_or_else(PoisonError::into_inner);
        }
        slot.done = false;
        slot.job.take()
    }

    /// Keeps a finished job's buffers for the next build.
    pub fn recycle(&mut self, job: Job) {
        self.idle = Some(job);
    }

    /// Forgets a build of `mesh` (the mesh was replaced or removed): its result is dropped
    /// when it arrives.
    pub fn cancel(&mut self, mesh: MeshId) {
        if self.busy == Some(mesh) {
            // Wait for it: the worker holds the buffers until then.
            let job = self.wait();
            self.busy = None;
            if let Some(job) = job {
                self.idle = Some(job);
            }
        }
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        if let Some(w) = self.worker.take() {
            self.shared
                .slot
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .quit = true;
            self.shared.wake.notify_all();
            let _ = w.join();
        }
    }
}

/// Moves the calling thread into the scheduler's idle class (Linux; kept at normal priority
/// where that is refused or elsewhere).
fn run_when_idle() {
    #[cfg(target_os = "linux")]
    {
        use thread_priority::{
            NormalThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
            set_thread_priority_and_policy, thread_native_id,
        };
        let _ = set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Min,
            ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle),
        );
    }
}

/// The worker: waits for a queued job, builds it, hands it back. Its builds and collapses run
/// in a pool of one thread of its own, so that their parallel steps (the collapse's subtrees,
/// its block fill) stay off the pool the frame traces on. `idle`: in the idle class.
fn work(shared: &Shared, idle: bool) {
    if idle {
        run_when_idle();
    }
    crate::cputime::waits_by_design();
    // The pool's thread inherits the worker's class.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .start_handler(|_| crate::cputime::waits_by_design())
        .build()
        .ok();
    loop {
        let mut slot = shared.slot.lock().unwrap_or_else(PoisonError::into_inner);
        while !slot.queued && !slot.quit {
            slot = shared
                .wake
                .wait(slot)
                .unwrap_or_else(PoisonError::into_inner);
        }
        if slot.quit {
            return;
        }
        slot.queued = false;
        let Some(mut job) = slot.job.take() else {
            continue;
        };
        drop(slot);
        let t = Instant::now();
        let params = job.params.unwrap_or(BuildParams::BINNED);
        let Job {
            positions,
            indices,
            tree,
            wide,
            ws,
            collapse,
            ..
        } = &mut job;
        let build = || {
            tree.rebuild_indexed(positions, indices, &params, ws);
            if let (true, Some(w)) = (*collapse, wide) {
                w.collapse_from(tree);
            }
        };
        match &pool {
            Some(p) => p.install(build),
            None => build(),
        }
        job.build_ms = t.elapsed().as_secs_f64() * 1e3;
        let mut slot = shared.slot.lock().unwrap_or_else(PoisonError::into_inner);
        slot.job = Some(job);
        slot.done = true;
        drop(slot);
        shared.wake.notify_all();
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    /// The scheduling policy of each of this process's threads (`/proc`'s field 41).
    fn policies() -> Vec<(String, u32)> {
        let mut out = Vec::new();
        for e in std::fs::read_dir("/proc/self/task")
            .into_iter()
            .flatten()
            .flatten()
        {
            let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
                continue;
            };
            // Fields after the command's closing parenthesis start at field 3.
            let rest = &stat[stat.rfind(')').map_or(0, |i| i + 1)..];
            if let Some(Ok(p)) = rest.split_ascii_whitespace().nth(41 - 3).map(str::parse) {
                out.push((e.file_name().to_string_lossy().into_owned(), p));
            }
        }
        out
    }

    #[test]
    fn the_worker_and_its_pool_run_in_the_idle_class_and_their_wait_is_not_load() {
        const SCHED_IDLE: u32 = 5;
        let before: Vec<String> = policies().into_iter().map(|(t, _)| t).collect();
        let mut b = Background::new(WorkerPriority::Idle);
        b.reserve(3, 1, &MeshBvh::default(), None);
        // The worker classes itself and starts its pool first thing; give them up to 10 s.
        let t = Instant::now();
        let new_idle = || {
            let mut v: Vec<String> = policies()
                .into_iter()
                .filter(|(tid, p)| *p == SCHED_IDLE && !before.contains(tid))
                .map(|(t, _)| t)
                .collect();
            v.sort();
            v
        };
        let settled = || {
            let new = new_idle();
            let marked = crate::cputime::waiting_by_design();
            new.len() == 2 && new.iter().all(|t| marked.contains(t))
        };
        while !settled() && t.elapsed().as_secs() < 10 {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let new = new_idle();
        assert_eq!(
            new.len(),
            2,
            "the worker and its pool's thread: {:?}",
            policies()
        );
        let marked = crate::cputime::waiting_by_design();
        assert!(
            new.iter().all(|t| marked.contains(t)),
            "{new:?} not all in {marked:?}"
        );
        // The worker is joined; its pool's thread ends on its own soon after.
        drop(b);
        let t = Instant::now();
        let gone = || {
            let marked = crate::cputime::waiting_by_design();
            !new.iter().any(|t| marked.contains(t))
        };
        while !gone() && t.elapsed().as_secs() < 10 {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        assert!(gone(), "still marked after the worker quit");
    }
}

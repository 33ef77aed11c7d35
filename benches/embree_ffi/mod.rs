//! Embree 3 (the system's `libembree3`, Debian `libembree-dev`) as a peer in the `peers`
//! benchmark, behind the opt-in `embree` feature: the default build and CI need no C library.
//!
//! Only the dozen entry points the harness uses are declared, from `embree3/rtcore_*.h`
//! (Embree 3.13). Every call into the library is `unsafe` and carries a `// SAFETY:` note.
//! Embree's trees are 4- to 8-wide and not exposed, so no SAH figure is reported for them.

use super::Accel;
use dynbvh::geom::{Ray, TriMesh};
use std::ffi::{CString, c_char, c_int, c_uint, c_void};
use std::sync::OnceLock;

type RTCDevice = *mut c_void;
type RTCScene = *mut c_void;
type RTCGeometry = *mut c_void;

const RTC_GEOMETRY_TYPE_TRIANGLE: c_uint = 0;
const RTC_BUFFER_TYPE_INDEX: c_uint = 0;
const RTC_BUFFER_TYPE_VERTEX: c_uint = 1;
const RTC_FORMAT_UINT3: c_uint = 0x5003;
const RTC_FORMAT_FLOAT3: c_uint = 0x9003;
const RTC_BUILD_QUALITY_LOW: c_uint = 0;
const RTC_BUILD_QUALITY_MEDIUM: c_uint = 1;
const RTC_BUILD_QUALITY_REFIT: c_uint = 3;
const RTC_SCENE_FLAG_NONE: c_uint = 0;
const RTC_SCENE_FLAG_DYNAMIC: c_uint = 1;
const RTC_SCENE_FLAG_ROBUST: c_uint = 1 << 2;
const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: c_uint = 0;
const RTC_INTERSECT_CONTEXT_FLAG_COHERENT: c_uint = 1;
const RTC_INVALID_GEOMETRY_ID: c_uint = c_uint::MAX;

/// `struct RTCIntersectContext` with `RTC_MAX_INSTANCE_LEVEL_COUNT == 1` and no minimum width
/// (the Debian build's `rtcore_config.h`).
#[repr(C)]
struct RTCIntersectContext {
    flags: c_uint,
    filter: *const c_void,
    inst_id: [c_uint; 1],
}

impl RTCIntersectContext {
    /// What the header's inline `rtcInitIntersectContext` sets, with the coherence hint.
    fn new(coherent: bool) -> Self {
        Self {
            flags: if coherent {
                RTC_INTERSECT_CONTEXT_FLAG_COHERENT
            } else {
                RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT
            },
            filter: std::ptr::null(),
            inst_id: [RTC_INVALID_GEOMETRY_ID],
        }
    }
}

/// `struct RTCRayHit`: `RTCRay` then `RTCHit`, each 16-byte aligned.
#[repr(C, align(16))]
#[derive(Clone, Copy)]
pub struct RTCRayHit {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: c_uint,
    id: c_uint,
    flags: c_uint,
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: c_uint,
    geom_id: c_uint,
    inst_id: [c_uint; 1],
}

/// `struct RTCRayHit16`: the ray and hit fields of 16 rays, structure of arrays.
#[repr(C, align(64))]
struct RTCRayHit16 {
    org_x: [f32; 16],
    org_y: [f32; 16],
    org_z: [f32; 16],
    tnear: [f32; 16],
    dir_x: [f32; 16],
    dir_y: [f32; 16],
    dir_z: [f32; 16],
    time: [f32; 16],
    tfar: [f32; 16],
    mask: [c_uint; 16],
    id: [c_uint; 16],
    flags: [c_uint; 16],
    // `RTCHit16` starts on a 64-byte boundary: 12 arrays of 64 bytes above.
    ng_x: [f32; 16],
    ng_y: [f32; 16],
    ng_z: [f32; 16],
    u: [f32; 16],
    v: [f32; 16],
    prim_id: [c_uint; 16],
    geom_id: [c_uint; 16],
    inst_id: [c_uint; 16],
}

const _: () = assert!(std::mem::size_of::<RTCRayHit>() == 80);
const _: () = assert!(std::mem::size_of::<RTCRayHit16>() == 20 * 64);

#[link(name = "embree3")]
unsafe extern "C" {
    fn rtcNewDevice(config: *const c_char) -> RTCDevice;
    fn rtcNewScene(device: RTCDevice) -> RTCScene;
    fn rtcReleaseScene(scene: RTCScene);
    fn rtcSetSceneBuildQuality(scene: RTCScene, quality: c_uint);
    fn rtcSetSceneFlags(scene: RTCScene, flags: c_uint);
    fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> c_uint;
    fn rtcCommitScene(scene: RTCScene);
    fn rtcNewGeometry(device: RTCDevice, kind: c_uint) -> RTCGeometry;
    fn rtcReleaseGeometry(geometry: RTCGeometry);
    fn rtcCommitGeometry(geometry: RTCGeometry);
    fn rtcSetGeometryBuildQuality(geometry: RTCGeometry, quality: c_uint);
    fn rtcSetNewGeometryBuffer(
        geometry: RTCGeometry,
        kind: c_uint,
        slot: c_uint,
        format: c_uint,
        byte_stride: usize,
        item_count: usize,
    ) -> *mut c_void;
    fn rtcUpdateGeometryBuffer(geometry: RTCGeometry, kind: c_uint, slot: c_uint);
    fn rtcIntersect1(scene: RTCScene, context: *mut RTCIntersectContext, rayhit: *mut RTCRayHit);
    fn rtcIntersect16(
        valid: *const c_int,
        scene: RTCScene,
        context: *mut RTCIntersectContext,
        rayhit: *mut RTCRayHit16,
    );
}

/// The process's one Embree device, on one thread like every library in the harness.
struct Device(RTCDevice);

// SAFETY: Embree devices may be used from any thread (the API is thread-safe for device,
// scene creation and queries); the harness only ever uses it from its one thread anyway.
unsafe impl Send for Device {}
// SAFETY: as above.
unsafe impl Sync for Device {}

fn device() -> RTCDevice {
    static DEVICE: OnceLock<Device> = OnceLock::new();
    DEVICE
        .get_or_init(|| {
            let config = CString::new(format!("threads={}", super::threads())).expect("no NUL");
            // SAFETY: `config` is a NUL-terminated string that outlives the call.
            let d = unsafe { rtcNewDevice(config.as_ptr()) };
            assert!(!d.is_null(), "Embree: rtcNewDevice failed");
            Device(d)
        })
        .0
}

/// How a variant builds and traces.
#[derive(Clone, Copy)]
pub enum Mode {
    /// Default build quality (MEDIUM), single rays (`rtcIntersect1`).
    Medium,
    /// Default build quality, packets of 16 (`rtcIntersect16`).
    MediumPackets,
    /// As `Medium` with the scene flag ROBUST: robust traversal and no optimisations that
    /// reduce arithmetic accuracy (Embree's manual), the nearest Embree comes to the exact
    /// walks dynbvh always runs.
    MediumRobust,
    /// As `MediumPackets` with the scene flag ROBUST.
    MediumRobustPackets,
    /// LOW quality, dynamic scene, geometry REFIT: the setting for deforming meshes, the only
    /// one in which Embree refits rather than rebuilds on a vertex update.
    LowRefit,
}

/// An Embree scene holding one triangle mesh.
pub struct Embree {
    scene: RTCScene,
    geometry: RTCGeometry,
    vertices: *mut [f32; 3],
    vertex_count: usize,
    mode: Mode,
}

// SAFETY: through a shared reference an `Embree` only traces (`rtcIntersect1`,
// `rtcIntersect16` on its committed scene), which Embree allows from any number of threads at
// once; what changes the scene or its vertex buffer (refit, drop) takes `&mut self`.
unsafe impl Sync for Embree {}

impl Drop for Embree {
    fn drop(&mut self) {
        // SAFETY: both handles were made by `build` and are released exactly once here.
        unsafe {
            rtcReleaseGeometry(self.geometry);
            rtcReleaseScene(self.scene);
        }
    }
}

/// Builds the Embree scene of `mesh` (the copy into Embree's buffers is part of its build, as
/// in Embree's own tutorials).
pub fn build(mesh: TriMesh, mode: Mode) -> Embree {
    let dev = device();
    let (quality, flags, geom_quality) = match mode {
        Mode::Medium | Mode::MediumPackets => (
            RTC_BUILD_QUALITY_MEDIUM,
            RTC_SCENE_FLAG_NONE,
            RTC_BUILD_QUALITY_MEDIUM,
        ),
        Mode::MediumRobust | Mode::MediumRobustPackets => (
            RTC_BUILD_QUALITY_MEDIUM,
            RTC_SCENE_FLAG_ROBUST,
            RTC_BUILD_QUALITY_MEDIUM,
        ),
        Mode::LowRefit => (
            RTC_BUILD_QUALITY_LOW,
            RTC_SCENE_FLAG_DYNAMIC,
            RTC_BUILD_QUALITY_REFIT,
        ),
    };
    let nv = mesh.positions.len();
    let nt = mesh.indices.len();
    // SAFETY: `dev` is a live device; each buffer Embree allocates here holds exactly the
    // item count asked for (plus its own padding), and is written within that count before
    // the geometry is committed; the scene takes its own reference to the geometry.
    unsafe {
        let scene = rtcNewScene(dev);
        rtcSetSceneBuildQuality(scene, quality);
        rtcSetSceneFlags(scene, flags);
        let geometry = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetGeometryBuildQuality(geometry, geom_quality);
        let vertices = rtcSetNewGeometryBuffer(
            geometry,
            RTC_BUFFER_TYPE_VERTEX,
            0,
            RTC_FORMAT_FLOAT3,
            12,
            nv,
        ) as *mut [f32; 3];
        let indices =
            rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt)
                as *mut [u32; 3];
        assert!(
            !vertices.is_null() && !indices.is_null(),
            "Embree: no buffer"
        );
        std::slice::from_raw_parts_mut(vertices, nv)
            .iter_mut()
            .zip(&mesh.positions)
            .for_each(|(d, p)| *d = p.to_array());
        std::slice::from_raw_parts_mut(indices, nt).copy_from_slice(&mesh.indices);
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(scene, geometry);
        rtcCommitScene(scene);
        Embree {
            scene,
            geometry,
            vertices,
            vertex_count: nv,
            mode,
        }
    }
}

impl Accel for Embree {
    type Input = TriMesh;
    type R = RTCRayHit;

    fn prepare(mesh: &TriMesh) -> TriMesh {
        mesh.clone()
    }

    fn ray(r: &Ray) -> RTCRayHit {
        RTCRayHit {
            org: r.origin().to_array(),
            tnear: r.tmin,
            dir: r.dir().to_array(),
            time: 0.0,
            tfar: r.tmax,
            mask: c_uint::MAX,
            id: 0,
            flags: 0,
            ng: [0.0; 3],
            u: 0.0,
            v: 0.0,
            prim_id: RTC_INVALID_GEOMETRY_ID,
            geom_id: RTC_INVALID_GEOMETRY_ID,
            inst_id: [RTC_INVALID_GEOMETRY_ID],
        }
    }

    #[inline]
    fn closest(&self, ray: &RTCRayHit) -> Option<(f32, u32)> {
        let mut rh = *ray;
        let mut ctx = RTCIntersectContext::new(false);
        // SAFETY: the scene is committed; `ctx` and `rh` are valid, aligned and live for the call.
        unsafe { rtcIntersect1(self.scene, &mut ctx, &mut rh) };
        (rh.geom_id != RTC_INVALID_GEOMETRY_ID).then_some((rh.tfar, rh.prim_id))
    }

    fn trace_all(&self, rays: &[RTCRayHit]) -> f32 {
        if !matches!(self.mode, Mode::MediumPackets | Mode::MediumRobustPackets) {
            return rays
                .iter()
                .filter_map(|r| self.closest(std::hint::black_box(r)))
                .map(|h| h.0)
                .sum();
        }
        let mut ctx = RTCIntersectContext::new(true);
        let mut p = Box::new(RTCRayHit16 {
            org_x: [0.0; 16],
            org_y: [0.0; 16],
            org_z: [0.0; 16],
            tnear: [0.0; 16],
            dir_x: [0.0; 16],
            dir_y: [0.0; 16],
            dir_z: [0.0; 16],
            time: [0.0; 16],
            tfar: [0.0; 16],
            mask: [c_uint::MAX; 16],
            id: [0; 16],
            flags: [0; 16],
            ng_x: [0.0; 16],
            ng_y: [0.0; 16],
            ng_z: [0.0; 16],
            u: [0.0; 16],
            v: [0.0; 16],
            prim_id: [0; 16],
            geom_id: [0; 16],
            inst_id: [0; 16],
        });
        let mut sum = 0.0;
        for chunk in rays.chunks(16) {
            let mut valid = [0 as c_int; 16];
            for (k, r) in chunk.iter().enumerate() {
                valid[k] = -1;
                p.org_x[k] = r.org[0];
                p.org_y[k] = r.org[1];
                p.org_z[k] = r.org[2];
                p.tnear[k] = r.tnear;
                p.dir_x[k] = r.dir[0];
                p.dir_y[k] = r.dir[1];
                p.dir_z[k] = r.dir[2];
                p.tfar[k] = r.tfar;
                p.geom_id[k] = RTC_INVALID_GEOMETRY_ID;
            }
            // SAFETY: `valid` has 16 lanes, `p` is a 64-byte-aligned RTCRayHit16 and `ctx` a
            // valid context, all live for the call; the scene is committed.
            unsafe { rtcIntersect16(valid.as_ptr(), self.scene, &mut ctx, &mut *p) };
            for k in 0..chunk.len() {
                if p.geom_id[k] != RTC_INVALID_GEOMETRY_ID {
                    sum += p.tfar[k];
                }
            }
        }
        sum
    }

    fn sah(&self) -> f64 {
        f64::NAN
    }

    fn refit(&mut self, input: &TriMesh) -> bool {
        if !matches!(self.mode, Mode::LowRefit) {
            // At MEDIUM quality a commit after a vertex update is a full rebuild.
            return false;
        }
        assert_eq!(input.positions.len(), self.vertex_count);
        // SAFETY: `vertices` is the geometry's own vertex buffer of `vertex_count` items, alive
        // as long as the geometry; nothing else reads it while it is written here.
        unsafe {
            std::slice::from_raw_parts_mut(self.vertices, self.vertex_count)
                .iter_mut()
                .zip(&input.positions)
                .for_each(|(d, p)| *d = p.to_array());
            rtcUpdateGeometryBuffer(self.geometry, RTC_BUFFER_TYPE_VERTEX, 0);
            rtcCommitGeometry(self.geometry);
            rtcCommitScene(self.scene);
        }
        true
    }
}

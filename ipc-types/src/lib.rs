//! The sample types that shoal's processes exchange over iceoryx2, the one
//! table of channels and sample types, and the functions that build their
//! service names; besides them only [`SonarScan`], the decoded sonar sample
//! that the sonar and planner libraries share. Nothing else lives here.
//!
//! Every sample is `#[repr(C)]`, `Copy`, fixed-size, pointer-free and
//! `bytemuck::Pod` (so every pad byte is an explicit `_padN` field), starts
//! with the common [`Header`], and carries a versioned iceoryx2 type name
//! (`shoal.Nav.v1`): a layout change is a new name, so iceoryx2 refuses a
//! mismatched peer instead of misreading it. Field names carry units and
//! frames. Frames: world NED (x north, y east, z down); body x forward,
//! y starboard, z down (Fossen). Quaternions are `[w, x, y, z]`, body → NED
//! unless the name says otherwise.
//!
//! ```
//! use ipc_types::{Nav, Sample, service_name, Channel};
//! let mut nav = Nav::zeroed();
//! nav.header.seq = 7;
//! assert_eq!(Nav::TYPE_NAME, "shoal.Nav.v1");
//! assert_eq!(service_name("ab12", "F1", Channel::Nav), "shoal/ab12/F1/nav");
//! let schema = ipc_types::schema::ros2msg_schema::<Nav>().unwrap();
//! assert!(schema.starts_with("shoal_msgs/Header header\n"));
//! ```

pub mod schema;

use iceoryx2::prelude::ZeroCopySend;
pub use schema::{Described, FieldDesc, FieldType, TypeDesc};

/// Most vehicles a run can hold (the world snapshot is fixed-size).
pub const MAX_VEHICLES: usize = 256;
/// Most sonar beams per vehicle.
pub const MAX_BEAMS: usize = 16;
/// Most light beacons on a parent.
pub const MAX_BEACONS: usize = 8;
/// Most remembered sonar returns a setpoint hands the controller's safety layer.
pub const MAX_KEEPOUT: usize = 8;

/// A sample type: a described, Pod, zero-copy struct with the common header.
pub trait Sample:
    Copy + bytemuck::Pod + ZeroCopySend + Described + Finite + std::fmt::Debug + Send + 'static
{
    /// The versioned iceoryx2 type name, e.g. `shoal.Nav.v1`.
    const TYPE_NAME: &'static str;
    /// The common header.
    fn header(&self) -> &Header;
    /// The common header, mutable.
    fn header_mut(&mut self) -> &mut Header;
    /// All-zero value (every sample type is valid when zeroed).
    fn zeroed() -> Self {
        bytemuck::Zeroable::zeroed()
    }
    /// True when every floating-point field is finite (a check generated
    /// per type by the declaring macro, see [`Finite`]; the schema-walking
    /// reference is [`schema::finite_by_schema`]). A type whose sample
    /// holds slots beyond its own count (the world snapshot) checks only
    /// the slots in use; a setpoint also checks its ranges.
    #[inline]
    fn is_finite(&self) -> bool {
        Finite::all_finite(self)
    }
}

/// A value whose floating-point contents can be checked for NaN and
/// infinities: `f64` and `f32` by value, integers always pass, arrays
/// element by element, described structs field by field (the `described!`
/// macro generates it, so a check compiles to straight-line code over the
/// type's floats with no schema, allocation or recursion at run time).
///
/// ```
/// use ipc_types::{Finite, World, Sample};
/// let mut w = World::zeroed();
/// assert!(w.all_finite());
/// w.vehicles[7].position_ned_m[1] = f64::NEG_INFINITY;
/// assert!(!w.all_finite());
/// assert!([1.0f32, 2.0].all_finite() && ![1.0f32, f32::NAN].all_finite());
/// ```
pub trait Finite {
    /// True when every floating-point value in `self` is finite.
    fn all_finite(&self) -> bool;

    /// True when every value of `items` is finite. Arrays check through
    /// this, so floats can override it with a branch-free bit test the
    /// compiler vectorises, and integers with a constant.
    #[inline]
    fn slice_all_finite(items: &[Self]) -> bool
    where
        Self: Sized,
    {
        items.iter().fold(true, |ok, v| ok & v.all_finite())
    }
}

macro_rules! finite_always {
    ($($t:ty),* $(,)?) => {
        $(impl Finite for $t {
            #[inline(always)]
            fn all_finite(&self) -> bool {
                true
            }
            #[inline(always)]
            fn slice_all_finite(_: &[Self]) -> bool {
                true
            }
        })*
    };
}
finite_always!(u64, i64, u32, i32, u16, i16, u8, i8);

/// Implements [`Finite`] for a float type. A float is not finite exactly
/// when its exponent bits are all ones; adding one unit of exponent to the
/// exponent bits then carries into the sign bit, so OR-ing that sum over a
/// slice and testing the sign bit checks every element with three integer
/// operations and no branch. Long slices (a 4 KiB sample's payload) take a
/// 256-bit copy of the same loop where the CPU has AVX2.
macro_rules! finite_float {
    ($($t:ty => $bits:ty, $exp:expr, $one:expr, $scan:ident, $scan_avx2:ident);* $(;)?) => {
        $(
        #[inline(always)]
        fn $scan(items: &[$t]) -> bool {
            const EXP: $bits = $exp;
            const ONE: $bits = $one;
            let acc = items
                .iter()
                .fold(0, |acc: $bits, v| acc | ((v.to_bits() & EXP) + ONE));
            acc >> (<$bits>::BITS - 1) == 0
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        fn $scan_avx2(items: &[$t]) -> bool {
            $scan(items)
        }

        impl Finite for $t {
            #[inline(always)]
            fn all_finite(&self) -> bool {
                <$t>::is_finite(*self)
            }
            #[inline]
            fn slice_all_finite(items: &[Self]) -> bool {
                #[cfg(target_arch = "x86_64")]
                if items.len() >= AVX2_MIN_LEN && std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2, checked on the line above.
                    #[allow(unsafe_code)]
                    return unsafe { $scan_avx2(items) };
                }
                $scan(items)
            }
        }
        )*
    };
}

/// Shortest float slice worth the AVX2 dispatch.
#[cfg(target_arch = "x86_64")]
const AVX2_MIN_LEN: usize = 64;

finite_float! {
    f64 => u64, 0x7ff0_0000_0000_0000, 0x0010_0000_0000_0000, scan_f64, scan_f64_avx2;
    f32 => u32, 0x7f80_0000, 0x0080_0000, scan_f32, scan_f32_avx2;
}

impl<T: Finite, const N: usize> Finite for [T; N] {
    #[inline]
    fn all_finite(&self) -> bool {
        T::slice_all_finite(self)
    }
}

/// Declares a `#[repr(C)]` Pod struct together with its self-description.
macro_rules! described {
    (
        $(#[$meta:meta])*
        pub struct $name:ident ($ros:literal, $tn:literal $(, measured = $m:literal)?) {
            $( $(#[$fmeta:meta])* pub $field:ident : $ty:ty ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable, ZeroCopySend)]
        #[type_name($tn)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: $ty ),*
        }
        impl Described for $name {
            const ROS_NAME: &'static str = $ros;
            $(const MEASURED: bool = $m;)?
            fn fields() -> Vec<FieldDesc> {
                vec![$( FieldDesc { name: schema::ros_field_name(stringify!($field)), ty: <$ty as FieldType>::describe() } ),*]
            }
        }
        impl FieldType for $name {
            fn describe() -> TypeDesc {
                TypeDesc::Nested { ros: $ros, fields: <$name as Described>::fields }
            }
        }
        impl $crate::Finite for $name {
            #[inline]
            fn all_finite(&self) -> bool {
                true $( & $crate::Finite::all_finite(&self.$field) )*
            }
        }
    };
}

/// Declares a sample type: a described struct whose first field is `header`.
macro_rules! sample {
    (
        $(#[$meta:meta])*
        pub struct $name:ident ($ros:literal, $tn:literal, size = $size:expr $(, measured = $m:literal)? $(, finite = $finite:path)?) {
            $( $(#[$fmeta:meta])* pub $field:ident : $ty:ty ),* $(,)?
        }
    ) => {
        described! {
            $(#[$meta])*
            pub struct $name ($ros, $tn $(, measured = $m)?) {
                $( $(#[$fmeta])* pub $field: $ty ),*
            }
        }
        impl Sample for $name {
            const TYPE_NAME: &'static str = $tn;
            fn header(&self) -> &Header { &self.header }
            fn header_mut(&mut self) -> &mut Header { &mut self.header }
            $(
            #[inline]
            fn is_finite(&self) -> bool { $finite(self) }
            )?
        }
        const _: () = assert!(std::mem::size_of::<$name>() == $size);
        const _: () = assert!(std::mem::align_of::<$name>() == 8);
    };
}

pub mod bench;

described! {
    /// The header every sample starts with.
    ///
    /// Wall-clock stamps are `CLOCK_MONOTONIC` nanoseconds, one clock shared by
    /// every process on the machine, so differences between processes are
    /// latencies. They are the only fields that differ between two lockstep
    /// runs of the same scenario and seed.
    pub struct Header("shoal_msgs/msg/Header", "shoal.Header.v1") {
        /// Per-publisher sequence number, from 0, no gaps unless samples were lost.
        pub seq: u64,
        /// Simulation time of this sample, ns since the run started.
        pub sim_time_ns: u64,
        /// Monotonic wall time when the sample was published, ns.
        pub publish_mono_ns: u64,
        /// Monotonic wall time of the sensor event this sample descends from, ns.
        pub origin_mono_ns: u64,
        /// Simulation time of that sensor event, ns.
        pub origin_sim_time_ns: u64,
    }
}
const _: () = assert!(std::mem::size_of::<Header>() == 40);

impl Header {
    /// Names of the fields that hold wall-clock stamps (excluded from
    /// determinism hashes).
    pub const WALL_CLOCK_FIELDS: [&'static str; 2] = ["publish_mono_ns", "origin_mono_ns"];
}

sample! {
    /// Ground truth of one vehicle, published by sim-plant. Only sensor
    /// simulators, the world process and the recorder may read it.
    pub struct Truth("shoal_msgs/msg/Truth", "shoal.Truth.v1", size = 232) {
        /// Common header.
        pub header: Header,
        /// Position of the centre of origin in NED, m.
        pub position_ned_m: [f64; 3],
        /// Attitude body → NED, `[w, x, y, z]`.
        pub q_body_to_ned_wxyz: [f64; 4],
        /// Roll, pitch, yaw (ZYX Euler), rad; for plots only.
        pub euler_rpy_rad: [f64; 3],
        /// Linear velocity in body axes, m/s.
        pub velocity_body_mps: [f64; 3],
        /// Angular rates in body axes, rad/s.
        pub rates_body_radps: [f64; 3],
        /// Generalised force applied (after saturation): N, N, N, N·m, N·m, N·m.
        pub tau_applied: [f64; 6],
        /// `origin_mono_ns` of the thrust sample applied in this step (0: none yet).
        pub thrust_origin_mono_ns: u64,
        /// Monotonic wall time at which that thrust was first applied, ns.
        pub thrust_applied_mono_ns: u64,
    }
}

sample! {
    /// What the vehicle's own navigation sensors report (AHRS, DVL, depth;
    /// absolute position only for the leader).
    pub struct Nav("shoal_msgs/msg/Nav", "shoal.Nav.v1", size = 184) {
        /// Common header.
        pub header: Header,
        /// Measured attitude body → NED, `[w, x, y, z]`.
        pub q_body_to_ned_wxyz: [f64; 4],
        /// Measured roll, pitch, yaw, rad.
        pub euler_rpy_rad: [f64; 3],
        /// Measured angular rates in body axes, rad/s.
        pub rates_body_radps: [f64; 3],
        /// Measured velocity over ground in body axes (DVL), m/s.
        pub velocity_body_mps: [f64; 3],
        /// Measured depth, m (positive down).
        pub depth_m: f64,
        /// Absolute position NED, m; valid only where `position_valid` is 1.
        pub position_ned_m: [f64; 3],
        /// 1 if `position_ned_m` is a measurement (leader only), else 0.
        pub position_valid: u8,
        /// Explicit padding.
        pub _pad0: [u8; 7],
    }
}

sample! {
    /// Generalised thrust command, published by mpc and applied by sim-plant.
    pub struct Thrust("shoal_msgs/msg/Thrust", "shoal.Thrust.v1", size = 96) {
        /// Common header.
        pub header: Header,
        /// Forces N (x, y, z) and moments N·m (x, y, z) in body axes, saturated.
        pub tau: [f64; 6],
        /// 1 if this command is the solver-failure fallback, else 0.
        pub fallback: u8,
        /// Bit i set when axis i hit its thrust limit.
        pub saturated_mask: u8,
        /// Explicit padding.
        pub _pad0: [u8; 6],
    }
}

described! {
    /// One vehicle's pose inside the world snapshot.
    pub struct VehiclePose("shoal_msgs/msg/VehiclePose", "shoal.VehiclePose.v1") {
        /// Position NED, m.
        pub position_ned_m: [f64; 3],
        /// Attitude body → NED, `[w, x, y, z]`.
        pub q_body_to_ned_wxyz: [f64; 4],
        /// Velocity in NED, m/s.
        pub velocity_ned_mps: [f64; 3],
    }
}

sample! {
    /// One fixed-size snapshot of every vehicle's true pose, published by the
    /// world process so sensors read one sample instead of every `truth`.
    pub struct World("shoal_msgs/msg/World", "shoal.World.v1", size = 48 + 80 * MAX_VEHICLES, finite = world_is_finite) {
        /// Common header.
        pub header: Header,
        /// Number of vehicles in `vehicles` (scenario order).
        pub count: u32,
        /// Bit-free flags: number of vehicles whose truth is older than this tick.
        pub stale: u32,
        /// Poses in scenario order.
        pub vehicles: [VehiclePose; MAX_VEHICLES],
    }
}

/// [`Sample::is_finite`] of a world snapshot: the floats that are part of
/// it, the header's and the first `count` vehicles' (all of them when
/// `count` is out of range). The world writes only those, in place, and
/// every reader reads only those ([`World::poses`]); the rest of the
/// fixed-size sample is whatever the chunk held before (zeros), and
/// checking it too read 20 KB a take: from memory, 1.9 µs against 0.5 for
/// a run of 5 vehicles, 3.3 against 1.1 for 100.
#[inline]
fn world_is_finite(w: &World) -> bool {
    w.header.all_finite() & VehiclePose::slice_all_finite(w.poses())
}

impl World {
    /// The snapshot's vehicles: the first `count` (every slot when
    /// `count` is out of range).
    #[inline]
    pub fn poses(&self) -> &[VehiclePose] {
        let n = usize::try_from(self.count).unwrap_or(usize::MAX);
        &self.vehicles[..n.min(MAX_VEHICLES)]
    }
}

sample! {
    /// A rangefinder scan: n ranges with beam angles and validity.
    pub struct Sonar("shoal_msgs/msg/Sonar", "shoal.Sonar.v2", size = 448) {
        /// Common header.
        pub header: Header,
        /// Measured range per beam, m; meaningful where `valid` is 1.
        pub ranges_m: [f64; MAX_BEAMS],
        /// Direction of the return in body axes, azimuth (positive to starboard), rad:
        /// the echo's own for a split beam with a return, else the beam's axis.
        pub azimuth_rad: [f64; MAX_BEAMS],
        /// Direction of the return in body axes, elevation (positive down), rad (as
        /// `azimuth_rad`).
        pub elevation_rad: [f64; MAX_BEAMS],
        /// 1 = return within range, 0 = no return.
        pub valid: [u8; MAX_BEAMS],
        /// Number of beams in use.
        pub count: u32,
        /// Explicit padding.
        pub _pad0: u32,
    }
}

/// One rangefinder scan as the libraries handle it: what the sonar library
/// produces and the planner reads, decoded from (and encoded into) a
/// [`Sonar`] sample. Entries `0..count` are the configured beams in order;
/// azimuth positive to starboard, elevation positive down, body axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SonarScan {
    /// Measured range per beam, m (meaningful where `valid`).
    pub ranges_m: [f64; MAX_BEAMS],
    /// Direction of the return, azimuth, rad (the echo's own for a split beam with a
    /// return, else the beam's axis).
    pub azimuth_rad: [f64; MAX_BEAMS],
    /// Direction of the return, elevation, rad (as `azimuth_rad`).
    pub elevation_rad: [f64; MAX_BEAMS],
    /// `false` = no return within range.
    pub valid: [bool; MAX_BEAMS],
    /// Beams in use.
    pub count: usize,
}

impl Default for SonarScan {
    fn default() -> Self {
        Self {
            ranges_m: [0.0; MAX_BEAMS],
            azimuth_rad: [0.0; MAX_BEAMS],
            elevation_rad: [0.0; MAX_BEAMS],
            valid: [false; MAX_BEAMS],
            count: 0,
        }
    }
}

impl SonarScan {
    /// The scan a [`Sonar`] sample carries (its count capped at [`MAX_BEAMS`]).
    pub fn from_sample(s: &Sonar) -> Self {
        Self {
            ranges_m: s.ranges_m,
            azimuth_rad: s.azimuth_rad,
            elevation_rad: s.elevation_rad,
            valid: s.valid.map(|v| v != 0),
            count: (s.count as usize).min(MAX_BEAMS),
        }
    }

    /// Writes the scan into a [`Sonar`] sample (the header untouched).
    pub fn write_to(&self, s: &mut Sonar) {
        s.ranges_m = self.ranges_m;
        s.azimuth_rad = self.azimuth_rad;
        s.elevation_rad = self.elevation_rad;
        s.valid = self.valid.map(u8::from);
        s.count = self.count.min(MAX_BEAMS) as u32;
    }

    /// Valid returns as `(range, azimuth, elevation)`, finite ones only.
    pub fn returns(&self) -> impl Iterator<Item = (f64, f64, f64)> + '_ {
        (0..self.count.min(MAX_BEAMS)).filter_map(move |i| {
            let (r, a, e) = (self.ranges_m[i], self.azimuth_rad[i], self.elevation_rad[i]);
            (self.valid[i] && r.is_finite() && a.is_finite() && e.is_finite() && r >= 0.0)
                .then_some((r, a, e))
        })
    }
}

sample! {
    /// Beacon pixels as the follower's camera sees its parent: with camera
    /// images, the centroids of the blobs identified as the parent's
    /// beacons (what was detected, never ground truth).
    pub struct Beacons("shoal_msgs/msg/Beacons", "shoal.Beacons.v2", size = 192) {
        /// Common header.
        pub header: Header,
        /// Pixel coordinates `u0, v0, u1, v1, ...`, px (origin top-left).
        pub pixels_uv: [f64; 2 * MAX_BEACONS],
        /// 1 if beacon i is visible in this frame (identified, with images).
        pub visible: [u8; MAX_BEACONS],
        /// Number of beacons on the parent.
        pub count: u32,
        /// Number visible in this frame.
        pub visible_count: u32,
        /// Blobs found in the image (every vehicle's lamps, any glare); 0
        /// with the point model.
        pub blobs: u32,
        /// Identification: 0 identified (or the point model), 1 the parent
        /// is not predicted in view, 2 too few blobs match its pattern,
        /// 3 ambiguous (another pattern fits as well).
        pub identification: u32,
    }
}

/// Most pixels of a camera frame (512 × 512, 8-bit mono: the paper's camera).
pub const MAX_IMAGE_BYTES: usize = 512 * 512;

sample! {
    /// One camera frame: 8-bit mono, row by row, written in place into
    /// shared memory by camera-sim and read in place by camera-pose. The
    /// first `height_px × step_bytes` bytes of `data` are the image.
    pub struct Image("shoal_msgs/msg/Image", "shoal.Image.v1", size = 40 + 16 + MAX_IMAGE_BYTES) {
        /// Common header (its simulation time is the exposure's).
        pub header: Header,
        /// Width, px.
        pub width_px: u32,
        /// Height, px.
        pub height_px: u32,
        /// Bytes from one row to the next.
        pub step_bytes: u32,
        /// Frame number of this camera, from 0.
        pub frame: u32,
        /// The pixels, `mono8`.
        pub data: [u8; MAX_IMAGE_BYTES],
    }
}

impl Image {
    /// The image's bytes (`height_px × step_bytes`, at most the buffer).
    pub fn pixels(&self) -> &[u8] {
        let n = (self.height_px as usize * self.step_bytes as usize).min(MAX_IMAGE_BYTES);
        &self.data[..n]
    }
}

/// `shoal/<run-id>/<vehicle>/image`: a follower's camera frames (only with
/// `[camera] model = "image"`; not in [`Channel::ALL`], whose channels every
/// vehicle or follower always has).
pub fn image_service_name(run_id: &str, vehicle: &str) -> String {
    format!("shoal/{run_id}/{vehicle}/image")
}

/// The MCAP topic of a follower's camera frames: `/<vehicle>/image`.
pub fn image_topic(vehicle: &str) -> String {
    format!("/{vehicle}/image")
}

sample! {
    /// The parent's pose in the follower's body frame, solved from beacon
    /// pixels alone (paper eqs. 1-3). Never a wild guess: see `valid`.
    pub struct LeaderPose("shoal_msgs/msg/LeaderPose", "shoal.LeaderPose.v1", size = 424) {
        /// Common header.
        pub header: Header,
        /// Parent position in the follower body frame (eq. 3), m.
        pub parent_position_body_m: [f64; 3],
        /// Parent attitude in the follower body frame (parent → follower body), `[w, x, y, z]`.
        pub q_parent_to_body_wxyz: [f64; 4],
        /// Follower position in the parent's body frame (eq. 1), m.
        pub follower_in_parent_m: [f64; 3],
        /// Covariance of `[position, rotation vector]` in the body frame (row-major 6×6).
        pub covariance: [f64; 36],
        /// Root-mean-square reprojection error, px.
        pub reprojection_rms_px: f64,
        /// 1 if the estimate is valid, else 0.
        pub valid: u8,
        /// Number of beacons the fit used.
        pub beacons_used: u8,
        /// Explicit padding.
        pub _pad0: [u8; 2],
        /// Solver iterations.
        pub iterations: u32,
    }
}

sample! {
    /// The target for mpc, in the vehicle's level frame: origin at the vehicle
    /// now, x along the current heading projected on the horizontal, y to
    /// starboard (horizontal), z down.
    pub struct Setpoint("shoal_msgs/msg/Setpoint", "shoal.Setpoint.v2", size = 352, finite = setpoint_is_valid) {
        /// Common header.
        pub header: Header,
        /// Where the vehicle should be, level frame, m.
        pub position_m: [f64; 3],
        /// How that target moves, level frame, m/s (feed-forward).
        pub velocity_mps: [f64; 3],
        /// Desired heading minus current heading, rad.
        pub yaw_rel_rad: f64,
        /// Planner mode (see the planner crate).
        pub mode: u32,
        /// Number of points in `keepout_m`, at most [`MAX_KEEPOUT`].
        pub keepout_count: u32,
        /// The remembered sonar returns nearest the vehicle, level frame, m, as
        /// `x0, y0, z0, x1, …`: the controller's safety layer keeps clear of them.
        pub keepout_m: [f64; 3 * MAX_KEEPOUT],
        /// The parent's estimated position, level frame, m (followers; see `parent_valid`).
        pub parent_position_m: [f64; 3],
        /// The parent's estimated velocity over ground, level frame axes, m/s.
        pub parent_velocity_mps: [f64; 3],
        /// 1 if the parent estimate is current (the controller keeps the safe distance
        /// from it), else 0.
        pub parent_valid: u32,
        /// Explicit padding.
        pub _pad0: u32,
    }
}

/// Farthest a [`Setpoint`]'s target may lie from its vehicle, m: a planner's
/// next waypoint is well within it; beyond it the value is garbage.
pub const SETPOINT_MAX_RANGE_M: f64 = 1.0e4;

/// Fastest a [`Setpoint`]'s target (or the parent estimate it carries) may
/// move, m/s: an AUV swims at a few.
pub const SETPOINT_MAX_SPEED_MPS: f64 = 100.0;

/// [`Sample::is_finite`] of a setpoint: every float finite, and every value
/// in its range (a target within [`SETPOINT_MAX_RANGE_M`], speeds within
/// [`SETPOINT_MAX_SPEED_MPS`], a turn within ±2π, at most [`MAX_KEEPOUT`]
/// returns, `parent_valid` 0 or 1). A planner may be the user's own program
/// (`[[replace]]`): what the controller and the recorder take from it is
/// checked like a sensor's.
fn setpoint_is_valid(s: &Setpoint) -> bool {
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    Finite::all_finite(s)
        && norm(&s.position_m) <= SETPOINT_MAX_RANGE_M
        && norm(&s.velocity_mps) <= SETPOINT_MAX_SPEED_MPS
        && s.yaw_rel_rad.abs() <= std::f64::consts::TAU
        && (s.keepout_count as usize) <= MAX_KEEPOUT
        && s.parent_valid <= 1
        && norm(&s.parent_position_m) <= SETPOINT_MAX_RANGE_M
        && norm(&s.parent_velocity_mps) <= SETPOINT_MAX_SPEED_MPS
}

/// What the controller's safety layer keeps clear of, as the planner hands it over with a
/// [`Setpoint`]: remembered sonar returns and the parent's estimate, in the vehicle's level
/// frame (origin at the vehicle now, x along its heading on the horizontal, y starboard,
/// z down). Only what the vehicle sensed: never ground truth.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Keepout {
    /// Returns, m; the first `count` are meaningful.
    pub points_m: [[f64; 3]; MAX_KEEPOUT],
    /// Number of returns in `points_m`.
    pub count: usize,
    /// The parent's estimated position (m) and velocity over ground (m/s), when current.
    pub parent: Option<([f64; 3], [f64; 3])>,
}

impl Keepout {
    /// The returns in use.
    pub fn points(&self) -> &[[f64; 3]] {
        &self.points_m[..self.count.min(MAX_KEEPOUT)]
    }

    /// Adds a return; false (and nothing added) when full or not finite.
    pub fn push(&mut self, p: [f64; 3]) -> bool {
        if self.count >= MAX_KEEPOUT || !p.iter().all(|x| x.is_finite()) {
            return false;
        }
        self.points_m[self.count] = p;
        self.count += 1;
        true
    }

    /// What a [`Setpoint`] carries (non-finite entries dropped, the count capped).
    pub fn from_setpoint(s: &Setpoint) -> Self {
        let mut k = Self::default();
        let n = (s.keepout_count as usize).min(MAX_KEEPOUT);
        for i in 0..n {
            k.push([
                s.keepout_m[3 * i],
                s.keepout_m[3 * i + 1],
                s.keepout_m[3 * i + 2],
            ]);
        }
        let finite = s
            .parent_position_m
            .iter()
            .chain(&s.parent_velocity_mps)
            .all(|x| x.is_finite());
        if s.parent_valid != 0 && finite {
            k.parent = Some((s.parent_position_m, s.parent_velocity_mps));
        }
        k
    }

    /// Writes it into a [`Setpoint`] (everything else untouched).
    pub fn write_to(&self, s: &mut Setpoint) {
        s.keepout_m = [0.0; 3 * MAX_KEEPOUT];
        for (i, p) in self.points().iter().enumerate() {
            s.keepout_m[3 * i..3 * i + 3].copy_from_slice(p);
        }
        s.keepout_count = self.points().len() as u32;
        let (p, v) = self.parent.unwrap_or_default();
        s.parent_position_m = p;
        s.parent_velocity_mps = v;
        s.parent_valid = u32::from(self.parent.is_some());
    }
}

sample! {
    /// The planner's internal state, for plots and debugging.
    pub struct PlannerState("shoal_msgs/msg/PlannerState", "shoal.PlannerState.v1", size = 144) {
        /// Common header.
        pub header: Header,
        /// Nominal slot in the parent's frame, m.
        pub slot_nominal_m: [f64; 3],
        /// Slot shifted for obstacle avoidance (eq. 8), parent frame, m.
        pub slot_shifted_m: [f64; 3],
        /// Low-pass filtered slot (eq. 9), parent frame, m.
        pub slot_filtered_m: [f64; 3],
        /// Smallest proximity δ of a sonar return to the predicted track (eq. 7), m.
        pub delta_min_m: f64,
        /// Age of the parent estimate, s.
        pub parent_age_s: f64,
        /// Distance to the current waypoint (leader), m.
        pub waypoint_distance_m: f64,
        /// Planner mode.
        pub mode: u32,
        /// 1 if the parent estimate is valid.
        pub parent_valid: u8,
        /// 1 while shifting to avoid an obstacle.
        pub avoiding: u8,
        /// Explicit padding.
        pub _pad0: [u8; 2],
    }
}

sample! {
    /// What the predictive controller did this step.
    pub struct MpcStats("shoal_msgs/msg/MpcStats", "shoal.MpcStats.v1", size = 72) {
        /// Common header.
        pub header: Header,
        /// Solve wall time, ns.
        pub solve_ns: u64,
        /// Optimal cost.
        pub cost: f64,
        /// Solver failures so far (cumulative).
        pub failures: u64,
        /// Solver iterations.
        pub iterations: u32,
        /// Solver status code (0 = solved).
        pub status: u32,
    }
}

sample! {
    /// The lockstep clock, published by the orchestrator before each tick.
    pub struct Clock("shoal_msgs/msg/Clock", "shoal.Clock.v1", size = 64) {
        /// Common header (`sim_time_ns` is the start of this tick).
        pub header: Header,
        /// Tick number, from 0.
        pub tick: u64,
        /// Tick length, ns.
        pub tick_ns: u64,
        /// 1 on the last tick of the run.
        pub last: u64,
    }
}

/// Most input channel kinds one process reports latency for.
pub const MAX_HOPS: usize = 12;

described! {
    /// Publish → take latency of one input channel kind of one process
    /// (every subscription of that kind merged), cumulative since the start.
    pub struct HopStats("shoal_msgs/msg/HopStats", "shoal.HopStats.v1") {
        /// Channel kind (`truth`, `world`, ...), NUL-padded ASCII.
        pub channel: [u8; 24],
        /// Samples taken.
        pub count: u64,
        /// Median, ns.
        pub p50_ns: u64,
        /// 99th percentile, ns.
        pub p99_ns: u64,
        /// 99.9th percentile, ns.
        pub p999_ns: u64,
        /// Largest, ns.
        pub max_ns: u64,
    }
}

sample! {
    /// One process's runtime statistics, cumulative since its start (the
    /// `recent_` fields: over the last publishing period), published
    /// on the run's `stats` channel about once a second (simulated time in
    /// lockstep, wall time in realtime) and recorded.
    pub struct ProcessStats("shoal_msgs/msg/ProcessStats", "shoal.ProcessStats.v2", size = 160 + 64 * MAX_HOPS, measured = true) {
        /// Common header.
        pub header: Header,
        /// Vehicle (`run` for run-level processes), NUL-padded ASCII.
        pub vehicle: [u8; 16],
        /// Process kind, NUL-padded ASCII.
        pub process: [u8; 16],
        /// Steps taken.
        pub steps: u64,
        /// Realtime: activations that started a whole period or more late.
        pub deadline_misses: u64,
        /// Samples lost (gaps in publishers' sequences), all inputs.
        pub lost: u64,
        /// Samples rejected for a non-finite value, all inputs.
        pub rejected: u64,
        /// Step duration (wake-up to step end) median, ns.
        pub step_p50_ns: u64,
        /// Step duration 99th percentile, ns.
        pub step_p99_ns: u64,
        /// Longest step, ns.
        pub step_max_ns: u64,
        /// Step duration median over the last publishing period (about a
        /// second), ns; 0 when it had no step.
        pub recent_step_p50_ns: u64,
        /// Step duration 99th percentile over the last publishing period, ns.
        pub recent_step_p99_ns: u64,
        /// Realtime: lateness of the wake-up after its activation time, 99th percentile, ns.
        pub wake_late_p99_ns: u64,
        /// Entries of `hops` in use.
        pub hop_count: u64,
        /// Per input channel kind.
        pub hops: [HopStats; MAX_HOPS],
    }
}

/// What an [`Event`] reports (its `kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum EventKind {
    /// A scenario `[[faults]]` entry struck (kill, stall).
    FaultInjected = 1,
    /// A process ended while the run needed it.
    ProcessDied = 2,
    /// A dead process was started again (policy `restart`).
    ProcessRestarted = 3,
    /// A restarted process is ready again: the gap is over.
    ProcessReady = 4,
    /// The run stopped early (policy `abort`, too many restarts, a hang).
    RunAborted = 5,
}

impl EventKind {
    /// Every kind.
    pub const ALL: [EventKind; 5] = [
        EventKind::FaultInjected,
        EventKind::ProcessDied,
        EventKind::ProcessRestarted,
        EventKind::ProcessReady,
        EventKind::RunAborted,
    ];

    /// Snake-case name, as in summary.json.
    pub const fn name(self) -> &'static str {
        match self {
            EventKind::FaultInjected => "fault_injected",
            EventKind::ProcessDied => "process_died",
            EventKind::ProcessRestarted => "process_restarted",
            EventKind::ProcessReady => "process_ready",
            EventKind::RunAborted => "run_aborted",
        }
    }

    /// The kind with code `code`.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|k| *k as u32 == code)
    }
}

sample! {
    /// Something that happened to the run's processes: an injected fault, a
    /// death, a restart, the end of a gap, an abort. Published by the
    /// orchestrator on the run's `events` channel (with history, so a
    /// restarted recorder still records the death that it was) and recorded
    /// as `/events`; the same events are listed in summary.json.
    pub struct Event("shoal_msgs/msg/Event", "shoal.Event.v1", size = 256) {
        /// Common header (`sim_time_ns`: simulated time of the event).
        pub header: Header,
        /// [`EventKind`] code.
        pub kind: u32,
        /// Index of the process in the run, `u32::MAX` for the run itself.
        pub process_index: u32,
        /// Restarts of this process so far (after this event).
        pub restarts: u32,
        /// Exit status of a dead process, or -1 (killed by a signal, or not a death).
        pub exit_code: i32,
        /// Signal that killed a dead process, or 0.
        pub signal: i32,
        /// Reserved (zero).
        pub reserved: u32,
        /// Wall time the process was gone (`process_ready`), or the stall's
        /// length (`fault_injected`), s; 0 otherwise.
        pub duration_s: f64,
        /// Wall time of the event, monotonic ns.
        pub event_mono_ns: u64,
        /// `vehicle/kind` of the process, NUL-padded ASCII.
        pub process: [u8; 32],
        /// Human-readable detail, NUL-padded UTF-8 (truncated).
        pub detail: [u8; 144],
    }
}

/// Copies `s` into a NUL-padded fixed-size ASCII field (truncating).
pub fn fixed_str<const N: usize>(s: &str) -> [u8; N] {
    let mut out = [0u8; N];
    for (o, b) in out.iter_mut().zip(s.bytes()) {
        *o = b;
    }
    out
}

/// Reads a NUL-padded fixed-size ASCII field.
pub fn str_of(b: &[u8]) -> &str {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    std::str::from_utf8(&b[..end]).unwrap_or("?")
}

/// Declares, from the one table below, the per-vehicle [`Channel`]s with
/// their names and sample types, and the macros through which every user of
/// "all channels" or "all sample types" (recorder, replay, the recording's
/// registry, pre-flight) expands it: [`with_channel_type!`],
/// [`with_sample_type!`], [`for_each_sample_type!`]. A new channel is one
/// line of the table (and its producer).
///
/// `$d` is a literal `$`, so that the macros it declares can have
/// metavariables of their own.
macro_rules! sample_table {
    (
        $d:tt
        vehicle { $( $(#[$cmeta:meta])* $V:ident = $vty:ident, $vname:literal; )* }
        run { $( $rty:ident ),* $(,)? }
    ) => {
        /// A per-vehicle channel of the channel table in DESIGN.md.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Channel {
            $( $(#[$cmeta])* $V ),*
        }

        impl Channel {
            /// Every per-vehicle channel.
            pub const ALL: [Channel; [$(stringify!($V)),*].len()] = [$(Channel::$V),*];

            /// The channel's name in service names and MCAP topics.
            pub const fn name(self) -> &'static str {
                match self {
                    $( Channel::$V => $vname ),*
                }
            }

            /// Size of the channel's sample, bytes.
            pub const fn sample_size(self) -> usize {
                match self {
                    $( Channel::$V => std::mem::size_of::<$vty>() ),*
                }
            }

            /// The ros2msg / MCAP schema name of the channel's sample.
            pub const fn schema_name(self) -> &'static str {
                match self {
                    $( Channel::$V => <$vty as Described>::ROS_NAME ),*
                }
            }
        }

        /// Every sample type's ros2msg / MCAP schema name: the per-vehicle
        /// channels' in [`Channel::ALL`] order, then the run-level ones.
        pub const SAMPLE_SCHEMAS: [&str; [$(stringify!($vty)),* , $(stringify!($rty)),*].len()] = [
            $( <$vty as Described>::ROS_NAME ),* ,
            $( <$rty as Described>::ROS_NAME ),*
        ];

        /// Evaluates `$body` with `$T` the sample type of a [`Channel`]:
        /// `with_channel_type!(ch, T => std::mem::size_of::<T>())`.
        #[macro_export]
        macro_rules! with_channel_type {
            ($d ch:expr, $d T:ident => $d body:expr) => {
                match $d ch {
                    $( $d crate::Channel::$V => {
                        #[allow(dead_code)]
                        #[allow(dead_code)]
                    type $d T = $d crate::$vty;
                        $d body
                    } )*
                }
            };
        }

        /// Evaluates `$body` with `$T` the sample type whose ros2msg schema
        /// name is `$schema` (`"shoal_msgs/msg/Nav"`, or the name recordings
        /// made before it used, `"shoal/Nav"`), or `$other` if none is.
        #[macro_export]
        macro_rules! with_sample_type {
            ($d schema:expr, $d T:ident => $d body:expr, else $d other:expr) => {{
                let canonical = $d crate::schema::canonical_schema_name($d schema);
                let schema: &str = &canonical;
                $( if schema == <$d crate::$vty as $d crate::Described>::ROS_NAME {
                    #[allow(dead_code)]
                    type $d T = $d crate::$vty;
                    $d body
                } else )*
                $( if schema == <$d crate::$rty as $d crate::Described>::ROS_NAME {
                    #[allow(dead_code)]
                    type $d T = $d crate::$rty;
                    $d body
                } else )*
                { $d other }
            }};
        }

        /// Runs `$body` once per sample type, with `$T` that type, in
        /// [`SAMPLE_SCHEMAS`] order.
        #[macro_export]
        macro_rules! for_each_sample_type {
            ($d T:ident => $d body:expr) => {{
                $( {
                    #[allow(dead_code)]
                    type $d T = $d crate::$vty;
                    $d body;
                } )*
                $( {
                    #[allow(dead_code)]
                    type $d T = $d crate::$rty;
                    $d body;
                } )*
            }};
        }
    };
}

sample_table! {
    $
    vehicle {
        /// [`Truth`]
        Truth = Truth, "truth";
        /// [`Nav`]
        Nav = Nav, "nav";
        /// [`Thrust`]
        Thrust = Thrust, "thrust";
        /// [`Sonar`]
        Sonar = Sonar, "sonar";
        /// [`Beacons`]
        Beacons = Beacons, "beacons";
        /// [`LeaderPose`]
        LeaderPose = LeaderPose, "leader_pose";
        /// [`Setpoint`]
        Setpoint = Setpoint, "setpoint";
        /// [`PlannerState`]
        PlannerState = PlannerState, "planner_state";
        /// [`MpcStats`]
        MpcStats = MpcStats, "mpc_stats";
    }
    run { World, Clock, ProcessStats, Event }
}

impl Channel {
    /// True for channels that carry ground truth.
    pub const fn is_ground_truth(self) -> bool {
        matches!(self, Channel::Truth)
    }

    /// True for channels only followers have (camera-pose output).
    pub const fn follower_only(self) -> bool {
        matches!(self, Channel::Beacons | Channel::LeaderPose)
    }
}

/// Run-level channels (one per run).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RunChannel {
    /// [`World`]
    World,
    /// [`Clock`]
    Clock,
    /// Event service on which every process reports a finished lockstep step.
    Done,
    /// [`ProcessStats`] of every process.
    Stats,
    /// [`Event`]s of the run, from the orchestrator.
    Events,
}

impl RunChannel {
    /// The channel's name in service names.
    pub const fn name(self) -> &'static str {
        match self {
            RunChannel::World => "world",
            RunChannel::Clock => "clock",
            RunChannel::Done => "done",
            RunChannel::Stats => "stats",
            RunChannel::Events => "events",
        }
    }
}

/// `shoal/<run-id>/<vehicle>/<channel>`.
pub fn service_name(run_id: &str, vehicle: &str, channel: Channel) -> String {
    format!("shoal/{run_id}/{vehicle}/{}", channel.name())
}

/// `shoal/<run-id>/<channel>` for run-level channels.
pub fn run_service_name(run_id: &str, channel: RunChannel) -> String {
    format!("shoal/{run_id}/{}", channel.name())
}

/// `shoal/<run-id>/<vehicle>/<process>/wake`: the lockstep wake-up event of one process.
pub fn wake_service_name(run_id: &str, vehicle: &str, process: &str) -> String {
    format!("shoal/{run_id}/{vehicle}/{process}/wake")
}

/// The MCAP topic of a per-vehicle channel: `/<vehicle>/<channel>`.
pub fn topic(vehicle: &str, channel: Channel) -> String {
    format!("/{vehicle}/{}", channel.name())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_sample_table_agrees_with_itself() {
        let mut seen = std::collections::BTreeSet::new();
        for s in SAMPLE_SCHEMAS {
            assert!(seen.insert(s), "{s} listed twice");
            let size = with_sample_type!(s, T => std::mem::size_of::<T>(), else 0);
            assert!(size > 0, "{s} has no type");
            assert_eq!(
                with_sample_type!(s, T => <T as Described>::ROS_NAME, else ""),
                s
            );
        }
        assert_eq!(with_sample_type!("shoal_msgs/msg/Nope", T => 1, else 0), 0);
        // Recordings made before the ROS 2 package names still resolve.
        assert_eq!(
            with_sample_type!("shoal/Truth", T => <T as Described>::ROS_NAME, else ""),
            "shoal_msgs/msg/Truth"
        );
        let mut n = 0;
        for_each_sample_type!(T => {
            check_layout::<T>();
            n += 1;
        });
        assert_eq!(n, SAMPLE_SCHEMAS.len());
        for (i, c) in Channel::ALL.into_iter().enumerate() {
            assert_eq!(SAMPLE_SCHEMAS[i], c.schema_name());
            assert_eq!(
                with_channel_type!(c, T => std::mem::size_of::<T>()),
                c.sample_size()
            );
        }
        assert_eq!(Channel::Nav.sample_size(), std::mem::size_of::<Nav>());
        assert_eq!(Channel::MpcStats.schema_name(), "shoal_msgs/msg/MpcStats");
        assert_eq!(SAMPLE_SCHEMAS.len(), Channel::ALL.len() + 4);
    }

    fn check_layout<T: Sample>() {
        assert_eq!(
            schema::cdr_size::<T>(),
            std::mem::size_of::<T>(),
            "{} has implicit padding or a field the schema misses",
            T::TYPE_NAME
        );
        let text = schema::ros2msg_schema::<T>().unwrap();
        assert!(text.contains("shoal_msgs/Header header"));
        assert!(!text.contains(" _"), "rust pad names leak into {text}");
    }

    /// Byte ranges of a field found by its offset in a zeroed sample.
    fn masked<T: Sample>(field: impl Fn(&mut T) -> &mut u64) -> bool {
        let mut v = <T as Sample>::zeroed();
        let base = &v as *const T as usize;
        let off = field(&mut v) as *mut u64 as usize - base;
        schema::wall_clock_ranges::<T>()
            .iter()
            .any(|r| r.start <= off && off + 8 <= r.end)
    }

    #[test]
    fn wall_clock_fields_are_masked_and_simulated_time_is_not() {
        assert!(masked::<Truth>(|t| &mut t.header.publish_mono_ns));
        assert!(masked::<Truth>(|t| &mut t.header.origin_mono_ns));
        assert!(masked::<Truth>(|t| &mut t.thrust_applied_mono_ns));
        assert!(!masked::<Truth>(|t| &mut t.header.sim_time_ns));
        assert!(!masked::<Truth>(|t| &mut t.header.origin_sim_time_ns));
        assert!(!masked::<Truth>(|t| &mut t.header.seq));
        assert!(masked::<MpcStats>(|m| &mut m.solve_ns));
        assert!(!masked::<Clock>(|c| &mut c.tick_ns));
        // Runtime statistics measure the machine (even their counts depend on
        // when samples were pulled): all but the header is masked.
        assert!(masked::<ProcessStats>(|p| &mut p.step_p99_ns));
        assert!(masked::<ProcessStats>(|p| &mut p.hops[3].p999_ns));
        assert!(masked::<ProcessStats>(|p| &mut p.steps));
        assert!(masked::<ProcessStats>(|p| &mut p.hops[3].count));
        assert!(!masked::<ProcessStats>(|p| &mut p.header.sim_time_ns));
        assert!(!masked::<ProcessStats>(|p| &mut p.header.seq));
    }

    #[test]
    fn every_sample_layout_matches_its_schema() {
        check_layout::<Truth>();
        check_layout::<Nav>();
        check_layout::<Thrust>();
        check_layout::<World>();
        check_layout::<Sonar>();
        check_layout::<Beacons>();
        check_layout::<LeaderPose>();
        check_layout::<Setpoint>();
        check_layout::<PlannerState>();
        check_layout::<MpcStats>();
        check_layout::<Clock>();
        check_layout::<ProcessStats>();
        check_layout::<Event>();
        check_layout::<Mixed>();
        check_layout::<Image>();
    }

    #[test]
    fn nested_types_get_msg_sections() {
        let text = schema::ros2msg_schema::<World>().unwrap();
        assert!(text.contains("shoal_msgs/VehiclePose[256] vehicles"));
        assert!(text.contains("MSG: shoal_msgs/VehiclePose\nfloat64[3] position_ned_m"));
        assert!(text.contains("MSG: shoal_msgs/Header\nuint64 seq"));
    }

    #[test]
    fn non_finite_values_are_detected() {
        let mut nav = Nav::zeroed();
        assert!(nav.is_finite());
        nav.depth_m = f64::NAN;
        assert!(!nav.is_finite());
        let mut w = World::zeroed();
        w.count = 201;
        w.vehicles[200].velocity_ned_mps[2] = f64::INFINITY;
        assert!(!w.is_finite());
    }

    #[test]
    fn service_names_separate_runs_and_vehicles() {
        assert_ne!(
            service_name("a", "F1", Channel::Nav),
            service_name("b", "F1", Channel::Nav)
        );
        assert_eq!(run_service_name("r", RunChannel::World), "shoal/r/world");
        assert_eq!(wake_service_name("r", "L", "mpc"), "shoal/r/L/mpc/wake");
    }

    sample! {
        /// Test-only sample mixing f32, integers of every width and nested
        /// arrays, so the generated check is exercised beyond f64 fields.
        pub struct Mixed("shoal_msgs/msg/Mixed", "shoal.Mixed.v1", size = 256) {
            /// Common header.
            pub header: Header,
            /// A single f32.
            pub a: f32,
            /// An f32 array.
            pub b: [f32; 5],
            /// A signed integer.
            pub c: i64,
            /// Nested structs in an array.
            pub poses: [VehiclePose; 2],
            /// Small integers.
            pub d: [i16; 3],
            /// More.
            pub e: u16,
            /// Explicit padding.
            pub _pad0: [i8; 8],
            /// An f64 after the integers.
            pub f: f64,
        }
    }

    /// Byte offset and width of every float of `T`, found from its schema.
    fn float_slots<T: Described>() -> Vec<(usize, usize)> {
        fn walk(ty: &TypeDesc, off: &mut usize, out: &mut Vec<(usize, usize)>) {
            match ty {
                TypeDesc::Primitive { ros, size } => {
                    *off = off.next_multiple_of(*size);
                    if ros.starts_with("float") {
                        out.push((*off, *size));
                    }
                    *off += size;
                }
                TypeDesc::Nested { fields, .. } => {
                    for f in fields() {
                        walk(&f.ty, off, out);
                    }
                }
                TypeDesc::Array { elem, len } => {
                    for _ in 0..*len {
                        walk(elem, off, out);
                    }
                }
            }
        }
        let (mut off, mut out) = (0, Vec::new());
        for f in T::fields() {
            walk(&f.ty, &mut off, &mut out);
        }
        out
    }

    /// A value of `T` with random integer bytes and random finite floats,
    /// then `inject` non-finite values written into the chosen floats
    /// (`(slot index, kind)`: NaN with a random payload, +inf, -inf).
    /// Returns the value and whether any injection landed.
    fn random_sample<T: Sample>(seed: u64, inject: &[(usize, u8)]) -> (T, bool) {
        let mut state = seed;
        let mut next = move || {
            // splitmix64
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        };
        let mut v = <T as Sample>::zeroed();
        let bytes = bytemuck::bytes_of_mut(&mut v);
        for chunk in bytes.chunks_mut(8) {
            let r = next().to_ne_bytes();
            chunk.copy_from_slice(&r[..chunk.len()]);
        }
        let slots = float_slots::<T>();
        for &(off, size) in &slots {
            let r = next();
            if size == 8 {
                // Clear one exponent bit when all are set: finite, any other value.
                let bits = if (r >> 52) & 0x7ff == 0x7ff {
                    r & !(1 << 60)
                } else {
                    r
                };
                bytes[off..off + 8].copy_from_slice(&bits.to_ne_bytes());
            } else {
                let r = r as u32;
                let bits = if (r >> 23) & 0xff == 0xff {
                    r & !(1 << 29)
                } else {
                    r
                };
                bytes[off..off + 4].copy_from_slice(&bits.to_ne_bytes());
            }
        }
        let injected = !slots.is_empty() && !inject.is_empty();
        for &(pick, kind) in inject {
            let Some(&(off, size)) = slots.get(pick % slots.len().max(1)) else {
                continue;
            };
            let payload = next();
            if size == 8 {
                let x = match kind % 3 {
                    0 => f64::from_bits(
                        0x7ff0_0000_0000_0000
                            | (payload & 0x000f_ffff_ffff_ffff).max(1)
                            | (payload & (1 << 63)),
                    ),
                    1 => f64::INFINITY,
                    _ => f64::NEG_INFINITY,
                };
                bytes[off..off + 8].copy_from_slice(&x.to_ne_bytes());
            } else {
                let p = payload as u32;
                let x = match kind % 3 {
                    0 => f32::from_bits(0x7f80_0000 | (p & 0x007f_ffff).max(1) | (p & (1 << 31))),
                    1 => f32::INFINITY,
                    _ => f32::NEG_INFINITY,
                };
                bytes[off..off + 4].copy_from_slice(&x.to_ne_bytes());
            }
        }
        (v, injected)
    }

    fn fast_equals_schema_walk<T: Sample>(
        seed: u64,
        inject: &[(usize, u8)],
    ) -> Result<(), TestCaseError> {
        let (v, injected) = random_sample::<T>(seed, inject);
        // The generated check of every float (the world's `is_finite`
        // narrows it to the slots in use: its own property below).
        let fast = Finite::all_finite(&v);
        prop_assert_eq!(
            fast,
            schema::finite_by_schema(&v),
            "{} seed {}",
            T::TYPE_NAME,
            seed
        );
        prop_assert_eq!(
            fast,
            !injected,
            "{} seed {} inject {:?}",
            T::TYPE_NAME,
            seed,
            inject
        );
        Ok(())
    }

    #[test]
    fn float_arrays_finite_at_the_edges() {
        let edge64 = [
            f64::MAX,
            -f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            -0.0,
            0.0,
            1.0,
        ];
        assert!(edge64.all_finite());
        for bad in [
            f64::NAN,
            -f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::from_bits(0x7ff0_0000_0000_0001),
        ] {
            for i in 0..edge64.len() {
                let mut a = edge64;
                a[i] = bad;
                assert!(!a.all_finite(), "{a:?}");
            }
        }
        let edge32 = [
            f32::MAX,
            -f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
            -0.0,
            0.0,
            1.0,
        ];
        assert!(edge32.all_finite());
        for bad in [
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::from_bits(0xff80_0001),
        ] {
            for i in 0..edge32.len() {
                let mut a = edge32;
                a[i] = bad;
                assert!(!a.all_finite(), "{a:?}");
            }
        }
        // Long arrays (the vectorised path where the CPU has one), each
        // position and each kind of non-finite value.
        let mut long64 = [0.0f64; 131];
        for (i, v) in long64.iter_mut().enumerate() {
            *v = edge64[i % edge64.len()];
        }
        assert!(long64.all_finite());
        let mut long32 = [0.0f32; 131];
        for (i, v) in long32.iter_mut().enumerate() {
            *v = edge32[i % edge32.len()];
        }
        assert!(long32.all_finite());
        for i in 0..131 {
            for (k, bad) in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY]
                .into_iter()
                .enumerate()
            {
                let mut a = long64;
                a[i] = bad;
                assert!(!a.all_finite(), "f64 {i} {k}");
                let mut b = long32;
                b[i] = bad as f32;
                assert!(!b.all_finite(), "f32 {i} {k}");
            }
        }
        assert!([u64::MAX; 4].all_finite() && [-1i8; 3].all_finite());
        let empty: [f64; 0] = [];
        assert!(empty.all_finite());
    }

    #[test]
    fn a_world_snapshot_ignores_what_lies_past_its_count() {
        let mut w = World::zeroed();
        w.count = 3;
        w.vehicles[3].position_ned_m[0] = f64::NAN;
        w.vehicles[MAX_VEHICLES - 1].velocity_ned_mps[2] = f64::INFINITY;
        assert!(w.is_finite() && !w.all_finite());
        w.vehicles[2].q_body_to_ned_wxyz[1] = f64::NAN;
        assert!(!w.is_finite());
        w.vehicles[2].q_body_to_ned_wxyz[1] = 0.0;
        w.header.sim_time_ns = u64::MAX;
        assert!(w.is_finite());
        // A count past the array checks every slot.
        w.count = u32::MAX;
        assert!(!w.is_finite() && w.poses().len() == MAX_VEHICLES);
    }

    #[test]
    fn float_slots_count_every_float() {
        assert_eq!(float_slots::<World>().len(), 10 * MAX_VEHICLES);
        assert_eq!(float_slots::<ProcessStats>().len(), 0);
        assert_eq!(float_slots::<Mixed>().len(), 1 + 5 + 20 + 1);
        assert_eq!(float_slots::<Truth>().len(), 22);
    }

    #[test]
    fn generated_check_covers_f32_and_nested_fields() {
        let mut m = Mixed::zeroed();
        assert!(m.is_finite());
        m.b[4] = f32::NAN;
        assert!(!m.is_finite() && !schema::finite_by_schema(&m));
        m.b[4] = 1.0;
        m.poses[1].q_body_to_ned_wxyz[3] = f64::INFINITY;
        assert!(!m.is_finite() && !schema::finite_by_schema(&m));
        m.poses[1].q_body_to_ned_wxyz[3] = 0.5;
        m.c = -1;
        m.e = u16::MAX;
        m._pad0 = [-1; 8];
        assert!(m.is_finite() && schema::finite_by_schema(&m));
        m.f = f64::NEG_INFINITY;
        assert!(!m.is_finite());
        // ProcessStats has no floats: any bytes pass.
        let (p, _) = random_sample::<ProcessStats>(3, &[]);
        assert!(p.is_finite() && schema::finite_by_schema(&p));
    }

    proptest! {
        #[test]
        fn generated_finite_check_equals_the_schema_walk(
            seed in any::<u64>(),
            inject in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..4),
        ) {
            fast_equals_schema_walk::<World>(seed, &inject)?;
            fast_equals_schema_walk::<ProcessStats>(seed, &inject)?;
            fast_equals_schema_walk::<Truth>(seed, &inject)?;
            fast_equals_schema_walk::<Nav>(seed, &inject)?;
            fast_equals_schema_walk::<Sonar>(seed, &inject)?;
            fast_equals_schema_walk::<LeaderPose>(seed, &inject)?;
            fast_equals_schema_walk::<PlannerState>(seed, &inject)?;
            fast_equals_schema_walk::<MpcStats>(seed, &inject)?;
            fast_equals_schema_walk::<Clock>(seed, &inject)?;
            fast_equals_schema_walk::<Mixed>(seed, &inject)?;
            fast_equals_schema_walk::<crate::bench::BenchPing4K>(seed, &inject)?;
        }

        #[test]
        fn a_world_snapshot_is_checked_over_the_vehicles_it_holds(
            seed in any::<u64>(),
            inject in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..4),
            count in prop_oneof![0u32..=MAX_VEHICLES as u32, any::<u32>()],
        ) {
            let (mut w, _) = random_sample::<World>(seed, &inject);
            w.count = count;
            // The same snapshot with every slot past `count` cleared.
            let mut held = w;
            let n = (count as usize).min(MAX_VEHICLES);
            held.vehicles[n..].fill(bytemuck::Zeroable::zeroed());
            prop_assert_eq!(w.poses().len(), n);
            prop_assert_eq!(w.is_finite(), schema::finite_by_schema(&held));
        }

        #[test]
        fn nav_bytes_round_trip(vals in proptest::collection::vec(-1e6f64..1e6, 17), seq in any::<u64>()) {
            let mut nav = Nav::zeroed();
            nav.header.seq = seq;
            nav.q_body_to_ned_wxyz.copy_from_slice(&vals[0..4]);
            nav.euler_rpy_rad.copy_from_slice(&vals[4..7]);
            nav.rates_body_radps.copy_from_slice(&vals[7..10]);
            nav.velocity_body_mps.copy_from_slice(&vals[10..13]);
            nav.depth_m = vals[13];
            nav.position_ned_m.copy_from_slice(&vals[14..17]);
            let bytes = bytemuck::bytes_of(&nav).to_vec();
            let back: Nav = bytemuck::pod_read_unaligned(&bytes);
            prop_assert_eq!(back, nav);
        }
    }
}

#[cfg(test)]
mod setpoint_range_tests {
    use super::*;

    #[test]
    fn a_setpoint_out_of_range_is_refused_like_a_non_finite_one() {
        let ok = Setpoint::zeroed();
        assert!(ok.is_finite());
        let bad: [fn(&mut Setpoint); 8] = [
            |s| s.position_m[0] = f64::NAN,
            |s| s.position_m[1] = 2.0 * SETPOINT_MAX_RANGE_M,
            |s| s.velocity_mps[2] = -2.0 * SETPOINT_MAX_SPEED_MPS,
            |s| s.yaw_rel_rad = 7.0,
            |s| s.keepout_count = MAX_KEEPOUT as u32 + 1,
            |s| s.parent_valid = 2,
            |s| s.parent_position_m[0] = 1e9,
            |s| s.parent_velocity_mps[0] = f64::INFINITY,
        ];
        for (i, spoil) in bad.iter().enumerate() {
            let mut s = ok;
            spoil(&mut s);
            assert!(!s.is_finite(), "case {i}");
        }
        let mut edge = ok;
        edge.position_m = [SETPOINT_MAX_RANGE_M, 0.0, 0.0];
        edge.keepout_count = MAX_KEEPOUT as u32;
        edge.yaw_rel_rad = -std::f64::consts::PI;
        assert!(edge.is_finite());
    }
}

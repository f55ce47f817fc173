//! Camera frames in a recording: written as the standard ROS 2
//! `sensor_msgs/msg/Image` (CDR), which the official MCAP readers decode and
//! Foxglove shows in its Image panel with no plug-in, and read back into
//! shoal's [`Image`] sample for replay.
//!
//! A frame's stamp is its exposure: the simulated time of the scene it
//! shows (the sample's origin; the MCAP log time is when it was published);
//! its `frame_id` is `<vehicle>_camera`; its encoding `mono8`. The
//! wall-clock stamps are not kept (they are the fields every comparison
//! ignores anyway).

use ipc_types::{Image, MAX_IMAGE_BYTES};

/// The schema name of a recorded camera frame.
pub const SCHEMA_NAME: &str = "sensor_msgs/msg/Image";

/// The ros2msg text of `sensor_msgs/msg/Image` with its dependencies.
pub const SCHEMA_TEXT: &str = "std_msgs/Header header\n\
uint32 height\n\
uint32 width\n\
string encoding\n\
uint8 is_bigendian\n\
uint32 step\n\
uint8[] data\n\
================================================================================\n\
MSG: std_msgs/Header\n\
builtin_interfaces/Time stamp\n\
string frame_id\n\
================================================================================\n\
MSG: builtin_interfaces/Time\n\
int32 sec\n\
uint32 nanosec\n";

/// The frame id of a vehicle's camera.
pub fn frame_id(vehicle: &str) -> String {
    format!("{vehicle}_camera")
}

fn align(out: &mut Vec<u8>, base: usize, to: usize) {
    while !(out.len() - base).is_multiple_of(to) {
        out.push(0);
    }
}

fn put_string(out: &mut Vec<u8>, base: usize, s: &str) {
    align(out, base, 4);
    out.extend_from_slice(&(s.len() as u32 + 1).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
    out.push(0);
}

/// Appends the CDR body (after the 4-byte encapsulation header) of `img`
/// as a `sensor_msgs/msg/Image` to `out`.
pub fn encode(img: &Image, frame_id: &str, out: &mut Vec<u8>) {
    let base = out.len();
    let t = img.header.origin_sim_time_ns;
    out.extend_from_slice(&((t / 1_000_000_000) as i32).to_le_bytes());
    out.extend_from_slice(&((t % 1_000_000_000) as u32).to_le_bytes());
    put_string(out, base, frame_id);
    align(out, base, 4);
    out.extend_from_slice(&img.height_px.to_le_bytes());
    out.extend_from_slice(&img.width_px.to_le_bytes());
    put_string(out, base, "mono8");
    out.push(0); // is_bigendian
    align(out, base, 4);
    out.extend_from_slice(&img.step_bytes.to_le_bytes());
    let pixels = img.pixels();
    out.extend_from_slice(&(pixels.len() as u32).to_le_bytes());
    out.extend_from_slice(pixels);
}

/// A recorded frame, as read.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame<'a> {
    /// Stamp, ns of simulation time.
    pub stamp_ns: u64,
    /// Frame id.
    pub frame_id: &'a str,
    /// Height, px.
    pub height: u32,
    /// Width, px.
    pub width: u32,
    /// Encoding (`mono8` for shoal's frames).
    pub encoding: &'a str,
    /// Bytes per row.
    pub step: u32,
    /// Pixels.
    pub data: &'a [u8],
}

struct Cursor<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn align(&mut self, to: usize) {
        self.at = self.at.div_ceil(to) * to;
    }
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.b.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        self.align(4);
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn string(&mut self) -> Option<&'a str> {
        let n = self.u32()? as usize;
        let s = self.take(n)?;
        std::str::from_utf8(s.strip_suffix(&[0])?).ok()
    }
}

/// Reads a stored `sensor_msgs/msg/Image` message (CDR header included).
pub fn read(data: &[u8]) -> Option<Frame<'_>> {
    let body = data.strip_prefix(&crate::CDR_HEADER)?;
    let mut c = Cursor { b: body, at: 0 };
    let sec = c.u32()? as i32;
    let nanosec = c.u32()?;
    let frame_id = c.string()?;
    let height = c.u32()?;
    let width = c.u32()?;
    let encoding = c.string()?;
    let _bigendian = c.take(1)?;
    let step = c.u32()?;
    let n = c.u32()? as usize;
    let data = c.take(n)?;
    Some(Frame {
        stamp_ns: u64::try_from(sec).ok()? * 1_000_000_000 + u64::from(nanosec),
        frame_id,
        height,
        width,
        encoding,
        step,
        data,
    })
}

/// Fills `out` from a stored frame (CDR header included) recorded with
/// MCAP sequence `seq`: the pixels, the size, and a header whose own and
/// origin simulated times are both the exposure (the sensor event). False if the message is not a `mono8` frame that fits.
pub fn to_sample(data: &[u8], seq: u64, out: &mut Image) -> bool {
    let Some(f) = read(data) else {
        return false;
    };
    let n = f.data.len();
    if f.encoding != "mono8" || n > MAX_IMAGE_BYTES || n != f.height as usize * f.step as usize {
        return false;
    }
    out.header = ipc_types::Header {
        seq,
        sim_time_ns: f.stamp_ns,
        publish_mono_ns: 0,
        origin_mono_ns: 0,
        origin_sim_time_ns: f.stamp_ns,
    };
    out.width_px = f.width;
    out.height_px = f.height;
    out.step_bytes = f.step;
    out.frame = seq as u32;
    out.data[..n].copy_from_slice(f.data);
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_goes_through_cdr_and_back() {
        let mut img: Box<Image> = bytemuck::zeroed_box();
        img.header.sim_time_ns = 12_365_678_901;
        img.header.origin_sim_time_ns = 12_345_678_901;
        img.width_px = 7;
        img.height_px = 3;
        img.step_bytes = 7;
        for (i, p) in img.data[..21].iter_mut().enumerate() {
            *p = i as u8 * 11;
        }
        let mut body = crate::CDR_HEADER.to_vec();
        encode(&img, &frame_id("F1"), &mut body);
        let f = read(&body).unwrap();
        assert_eq!(f.stamp_ns, 12_345_678_901);
        assert_eq!(f.frame_id, "F1_camera");
        assert_eq!((f.width, f.height, f.step, f.encoding), (7, 3, 7, "mono8"));
        assert_eq!(f.data, img.pixels());
        let mut back: Box<Image> = bytemuck::zeroed_box();
        assert!(to_sample(&body, 4, &mut back));
        assert_eq!(back.pixels(), img.pixels());
        assert_eq!(back.header.sim_time_ns, 12_345_678_901);
        assert_eq!(back.header.seq, 4);
        // Cut short: refused, not misread.
        assert!(read(&body[..body.len() - 1]).is_none());
    }
}

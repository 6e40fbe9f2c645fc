//! Per-frame jaw poses as CSV, for biomechanics: anatomical units first, then the pose itself.

use std::fmt::Write as _;

use crate::anatomy::motion::MotionFrame;
use crate::geometry::Pose;

/// The header line.
pub const HEADER: &str = "frame,time_s,status,opening_deg,incisal_opening_mm,lateral_mm,protrusion_mm,\
incisal_x_mm,incisal_y_mm,incisal_z_mm,tx_mm,ty_mm,tz_mm,qw,qx,qy,qz";

/// One row a frame: `(frame, time in s, status, upper_from_lower)`.
pub fn write_csv(motion: &MotionFrame, rows: &[(u32, f64, &str, Pose)]) -> String {
    let mut out = String::with_capacity(64 + rows.len() * 200);
    out.push_str(HEADER);
    out.push('\n');
    for (frame, time, status, jaw) in rows {
        let a = motion.measure(jaw);
        let p = jaw.transform_point(&motion.incisal_point());
        let t = jaw.translation;
        let q = nalgebra::UnitQuaternion::from_rotation_matrix(&jaw.rotation);
        let _ = writeln!(
            out,
            "{frame},{time:.6},{status},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.8},{:.8},{:.8},{:.8}",
            a.opening_deg,
            a.incisal_opening_mm,
            a.lateral_mm,
            a.protrusion_mm,
            p.x,
            p.y,
            p.z,
            t.x,
            t.y,
            t.z,
            q.w,
            q.i,
            q.j,
            q.k
        );
    }
    out
}

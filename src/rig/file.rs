//! The rig file (`jawtrack-rig/1`): written atomically, and read back only when every network,
//! mode, scaling and frame in it is one the rig can use, so that a hand-edited or foreign file
//! is refused with the field that is wrong rather than posing NaN.

use std::path::Path;

use super::model::{InputScaling, JawRig, NETWORK_COMPONENTS, RIG_FORMAT};
use crate::error::{Error, Result};
use crate::io::{read_json, write_json_atomic};

impl JawRig {
    /// Save as JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        write_json_atomic(path, self)
    }

    /// Read and check a rig file.
    pub fn load(path: &Path) -> Result<JawRig> {
        let mut rig: JawRig = read_json(path, "rig file")?;
        if rig.format != RIG_FORMAT {
            return Err(Error::invalid(
                path,
                "format",
                format!("expected {RIG_FORMAT:?}, found {:?}", rig.format),
            ));
        }
        let nets = [
            ("network", rig.network.as_ref(), NETWORK_COMPONENTS),
            ("paper.lateral", rig.paper.as_ref().map(|p| &p.lateral), 1),
            (
                "paper.protrusion",
                rig.paper.as_ref().map(|p| &p.protrusion),
                1,
            ),
        ];
        for (field, net, components) in nets {
            let Some(net) = net else { continue };
            net.check().map_err(|p| Error::invalid(path, field, p))?;
            if net.inputs != 6 || net.components != components {
                return Err(Error::invalid(
                    path,
                    field,
                    format!(
                        "expected 6 inputs and {components} components, found {} and {}",
                        net.inputs, net.components
                    ),
                ));
            }
        }
        if rig.paper.is_some() && rig.network.is_none() {
            return Err(Error::invalid(path, "network", "paper needs the network"));
        }
        // Rig files written before `input` took the network's scaling, which is the same.
        if rig.input == InputScaling::default()
            && let Some(net) = &rig.network
        {
            rig.input = InputScaling {
                mean: std::array::from_fn(|q| net.mean.get(q).copied().unwrap_or(f64::NAN)),
                scale: net.scale,
            };
        }
        crate::io::check_finite(path, "input.mean", &rig.input.mean)?;
        if !(rig.input.scale.is_finite() && rig.input.scale > 0.0) {
            return Err(Error::invalid(
                path,
                "input.scale",
                "must be a positive number",
            ));
        }
        rig.modes
            .check()
            .map_err(|p| Error::invalid(path, "modes", p))?;
        if rig.modes.dims != 6 {
            return Err(Error::invalid(path, "modes.dims", "must be 6"));
        }
        if let Some(c) = &rig.couplings {
            c.check()
                .map_err(|p| Error::invalid(path, "couplings", p))?;
            if c.dims != 6 {
                return Err(Error::invalid(path, "couplings.dims", "must be 6"));
            }
        }
        if let Some(k) = rig.gain.iter().position(|g| !g.is_finite() || *g == 0.0) {
            return Err(Error::invalid(
                path,
                format!("gain[{k}]"),
                "must be a finite, non-zero number",
            ));
        }
        if rig.probes_mm.is_empty() {
            return Err(Error::invalid(
                path,
                "probes_mm",
                "must list at least one point",
            ));
        }
        if let Some(a) = &rig.anatomy {
            a.rest.to_pose(path, "anatomy.rest")?;
            let f = &a.frame;
            let points = [f.condyle_left, f.condyle_right, f.reference];
            crate::io::check_finite(path, "anatomy.frame", points.as_flattened())?;
            f.axes()
                .map_err(|e| Error::invalid(path, "anatomy.frame", e.to_string()))?;
        }
        if !(rig.coords.radius_mm.is_finite() && rig.coords.radius_mm > 0.0) {
            return Err(Error::invalid(
                path,
                "coords.radius_mm",
                "must be a positive number",
            ));
        }
        Ok(rig)
    }
}

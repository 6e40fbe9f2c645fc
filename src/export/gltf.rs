//! Motion out to animation packages: a glTF 2.0 file (one .gltf, its buffer embedded) with
//! the upper arch fixed, the lower arch animated by the jaw pose and the mandible (when the
//! capture has one) riding on it. glTF's unit is the metre and its up axis +y, as the scan
//! frame's; positions and translations are scaled from millimetres.

use base64::Engine as _;
use gltf_json as json;
use json::validation::{Checked::Valid, USize64};

use crate::geometry::Pose;
use crate::mesh::Mesh;

/// A mesh to write, with its name and colour (linear RGBA).
pub struct Part<'a> {
    pub name: &'a str,
    pub mesh: &'a Mesh,
    pub colour: [f32; 4],
}

/// One key of the jaw's animation.
#[derive(Debug, Clone, Copy)]
pub struct Key {
    pub time_s: f32,
    /// `upper_from_lower`, mm.
    pub jaw: Pose,
}

/// The parts' colours in the files of tracked and keyed motion.
pub const UPPER_COLOUR: [f32; 4] = [0.95, 0.93, 0.88, 1.0];
pub const LOWER_COLOUR: [f32; 4] = [0.90, 0.92, 0.95, 1.0];
pub const MANDIBLE_COLOUR: [f32; 4] = [0.85, 0.80, 0.70, 1.0];

/// The keys of an animation played at `fps`: frame i at i / fps seconds.
pub fn keys_of(frames: &[crate::rig::animate::AnimatedFrame], fps: f64) -> Vec<Key> {
    frames
        .iter()
        .map(|f| Key {
            time_s: (f.frame as f64 / fps) as f32,
            jaw: f.pose,
        })
        .collect()
}

const MM: f32 = 0.001;

/// The bytes and accessors being built.
struct Builder {
    root: json::Root,
    bytes: Vec<u8>,
}

impl Builder {
    /// An empty glTF 2.0 document, signed by this version of jawtrack.
    fn new() -> Builder {
        let mut b = Builder {
            root: json::Root::default(),
            bytes: Vec::new(),
        };
        b.root.asset = json::Asset {
            generator: Some(format!("jawtrack {}", env!("CARGO_PKG_VERSION"))),
            version: "2.0".into(),
            ..Default::default()
        };
        b
    }

    fn view(
        &mut self,
        data: &[u8],
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::buffer::View> {
        let offset = self.bytes.len();
        self.bytes.extend_from_slice(data);
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64(data.len() as u64),
            byte_offset: Some(USize64(offset as u64)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        })
    }

    fn accessor(
        &mut self,
        data: &[u8],
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        target: Option<json::buffer::Target>,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
    ) -> json::Index<json::Accessor> {
        let view = self.view(data, target);
        let (min, max) = match bounds {
            Some((lo, hi)) => (Some(json::Value::from(lo)), Some(json::Value::from(hi))),
            None => (None, None),
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64(count as u64),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn floats(
        &mut self,
        values: &[f32],
        width: usize,
        bounded: bool,
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::Accessor> {
        let type_ = match width {
            1 => json::accessor::Type::Scalar,
            3 => json::accessor::Type::Vec3,
            _ => json::accessor::Type::Vec4,
        };
        let bounds = bounded.then(|| {
            let mut lo = vec![f32::INFINITY; width];
            let mut hi = vec![f32::NEG_INFINITY; width];
            for c in values.chunks(width) {
                for k in 0..width {
                    lo[k] = lo[k].min(c[k]);
                    hi[k] = hi[k].max(c[k]);
                }
            }
            (lo, hi)
        });
        self.accessor(
            bytemuck::cast_slice(values),
            values.len() / width,
            json::accessor::ComponentType::F32,
            type_,
            target,
            bounds,
        )
    }

    fn mesh(&mut self, part: &Part) -> json::Index<json::Mesh> {
        let m = part.mesh;
        let positions: Vec<f32> = m.positions.iter().flat_map(|p| p.map(|v| v * MM)).collect();
        let normals: Vec<f32> = m
            .vertex_normals()
            .iter()
            .flat_map(|n| {
                let v = n.map(|x| x as f32);
                let len = v.norm();
                if len > 1e-12 && len.is_finite() {
                    let u = v / len;
                    [u.x, u.y, u.z]
                } else {
                    [0.0, 1.0, 0.0]
                }
            })
            .collect();
        let indices: Vec<u32> = m.triangles.iter().flatten().copied().collect();
        let array = Some(json::buffer::Target::ArrayBuffer);
        let pos = self.floats(&positions, 3, true, array);
        let nor = self.floats(&normals, 3, false, array);
        let idx = self.accessor(
            bytemuck::cast_slice(&indices),
            indices.len(),
            json::accessor::ComponentType::U32,
            json::accessor::Type::Scalar,
            Some(json::buffer::Target::ElementArrayBuffer),
            None,
        );
        let material = self.root.push(json::Material {
            name: Some(part.name.to_string()),
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_factor: json::material::PbrBaseColorFactor(part.colour),
                metallic_factor: json::material::StrengthFactor(0.0),
                roughness_factor: json::material::StrengthFactor(0.6),
                ..Default::default()
            },
            ..Default::default()
        });
        let mut attributes = std::collections::BTreeMap::new();
        attributes.insert(Valid(json::mesh::Semantic::Positions), pos);
        attributes.insert(Valid(json::mesh::Semantic::Normals), nor);
        self.root.push(json::Mesh {
            extensions: None,
            extras: Default::default(),
            name: Some(part.name.to_string()),
            primitives: vec![json::mesh::Primitive {
                attributes,
                extensions: None,
                extras: Default::default(),
                indices: Some(idx),
                material: Some(material),
                mode: Valid(json::mesh::Mode::Triangles),
                targets: None,
            }],
            weights: None,
        })
    }

    /// A node holding `part`'s mesh, named as the part.
    fn node(&mut self, part: &Part) -> json::Index<json::Node> {
        let mesh = self.mesh(part);
        self.root.push(json::Node {
            mesh: Some(mesh),
            name: Some(part.name.to_string()),
            ..Default::default()
        })
    }

    /// The animation `name` of `node` by `keys`, linearly interpolated.
    fn animate(&mut self, node: json::Index<json::Node>, keys: &[Key], name: &str) {
        let times: Vec<f32> = keys.iter().map(|k| k.time_s).collect();
        let moves: Vec<f32> = keys.iter().flat_map(|k| translation(&k.jaw)).collect();
        let turns = short_way_turns(keys);
        let input = self.floats(&times, 1, true, None);
        let t_out = self.floats(&moves, 3, false, None);
        let r_out = self.floats(&turns, 4, false, None);
        let sampler = |output| json::animation::Sampler {
            extensions: None,
            extras: Default::default(),
            input,
            interpolation: Valid(json::animation::Interpolation::Linear),
            output,
        };
        let channel = |sampler: u32, path| json::animation::Channel {
            sampler: json::Index::new(sampler),
            target: json::animation::Target {
                extensions: None,
                extras: Default::default(),
                node,
                path: Valid(path),
            },
            extensions: None,
            extras: Default::default(),
        };
        self.root.push(json::Animation {
            extensions: None,
            extras: Default::default(),
            channels: vec![
                channel(0, json::animation::Property::Translation),
                channel(1, json::animation::Property::Rotation),
            ],
            name: Some(name.to_string()),
            samplers: vec![sampler(t_out), sampler(r_out)],
        });
    }

    /// The document, with the bytes embedded as its one buffer, as pretty JSON ending in a
    /// newline.
    fn finish(mut self) -> Vec<u8> {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bytes)
        );
        self.root.push(json::Buffer {
            byte_length: USize64(self.bytes.len() as u64),
            name: None,
            uri: Some(uri),
            extensions: None,
            extras: Default::default(),
        });
        let mut out = self.root.to_vec_pretty().expect("plain data serialises");
        out.push(b'\n');
        out
    }
}

fn translation(p: &Pose) -> [f32; 3] {
    let t = p.translation * MM as f64;
    [t.x as f32, t.y as f32, t.z as f32]
}

/// glTF's (x, y, z, w), unit length.
fn quaternion(p: &Pose) -> [f32; 4] {
    let q = nalgebra::UnitQuaternion::from_rotation_matrix(&p.rotation);
    let c = q.coords;
    [c.x as f32, c.y as f32, c.z as f32, c.w as f32]
}

/// The keys' rotations as glTF quaternions, flattened; neighbouring keys on the same side of
/// the quaternion sphere, so interpolation takes the short way.
fn short_way_turns(keys: &[Key]) -> Vec<f32> {
    let mut turns: Vec<f32> = Vec::with_capacity(keys.len() * 4);
    let mut last = [0.0f32, 0.0, 0.0, 1.0];
    for k in keys {
        let mut q = quaternion(&k.jaw);
        if q.iter().zip(&last).map(|(a, b)| a * b).sum::<f32>() < 0.0 {
            q = q.map(|v| -v);
        }
        turns.extend_from_slice(&q);
        last = q;
    }
    turns
}

/// The glTF document: `upper` (when given) at the root, fixed; `lower` animated by `keys`
/// (one key: posed, not animated); `mandible` as the lower arch's child. `animation` names
/// the animation.
pub fn write_gltf(
    upper: Option<&Part>,
    lower: &Part,
    mandible: Option<&Part>,
    keys: &[Key],
    animation: &str,
) -> Vec<u8> {
    let mut b = Builder::new();
    let upper_node = upper.map(|u| b.node(u));
    let lower_mesh = b.mesh(lower);
    let mandible_node = mandible.map(|m| b.node(m));
    let first = keys.first().map(|k| k.jaw).unwrap_or_default();
    let lower_node = b.root.push(json::Node {
        mesh: Some(lower_mesh),
        name: Some(lower.name.to_string()),
        translation: Some(translation(&first)),
        rotation: Some(json::scene::UnitQuaternion(quaternion(&first))),
        children: mandible_node.map(|n| vec![n]),
        ..Default::default()
    });
    let scene = b.root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("jaw".into()),
        nodes: upper_node.into_iter().chain([lower_node]).collect(),
    });
    b.root.scene = Some(scene);
    if keys.len() > 1 {
        b.animate(lower_node, keys, animation);
    }
    b.finish()
}

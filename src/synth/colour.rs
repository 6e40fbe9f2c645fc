//! Colour frames of a synthetic capture, as a camera would film them, and the true labels
//! they show: shaded crowns with highlights between the lips, the dark mouth interior, lips
//! and skin with some texture, sensor noise, and a light that can be switched off (the sync
//! event of the paper's Section 5). [`Photos::Hard`] adds what real footage of a mouth has
//! and the clean pictures lack: gums, the tongue, wet highlights, lips shading the crowns and
//! motion blur (white balance and exposure drift are the writer's, per frame). Surfaces are
//! given the colours a picture shows; they mix as light (over the shutter, through the lens)
//! and are encoded as a camera writes them ([`crate::capture::light`]).

use nalgebra::Vector3;
use rand::RngExt;

use super::masks::{self, LipLine};
use super::{LOWER_LABEL, MOUTH_LABEL, UPPER_LABEL};
use crate::arch::ArchPoses;
use crate::capture::light::{decoded, encoded};
use crate::energy::raster::{Target, render_target};
use crate::geometry::Camera;
use crate::mesh::Mesh;

/// What the camera sees of the subject: one frame's colour picture and its true labels.
pub struct ColourFrame {
    /// RGB, row-major, 3 bytes a pixel.
    pub rgb: Vec<u8>,
    /// The capture format's mask values: upper and lower crowns where visible, the mouth
    /// interior inside the lip opening, 0 elsewhere.
    pub labels: Vec<u8>,
}

/// The lighting of one picture.
#[derive(Debug, Clone, Copy)]
pub struct Exposure {
    /// Overall brightness (1: lights on; the lights off leave a few percent).
    pub gain: f64,
    /// Per-channel white balance of the camera.
    pub white: [f64; 3],
}

const TEETH: [f64; 3] = [232.0, 222.0, 196.0];
const MOUTH: [f64; 3] = [70.0, 24.0, 30.0];
const LIP: [f64; 3] = [172.0, 84.0, 88.0];
const SKIN: [f64; 3] = [212.0, 164.0, 138.0];
const GUM: [f64; 3] = [196.0, 96.0, 108.0];
const TONGUE: [f64; 3] = [178.0, 88.0, 96.0];
/// How much gum shows beyond the crowns, where the lips leave it (mm at the subject).
const GUM_MM: f64 = 2.0;

/// How tall the lips are beyond the opening (mm at the subject).
const LIP_HEIGHT_MM: f64 = 9.0;

/// How hard the pictures are to read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Photos {
    /// Teeth, the dark mouth interior, lips and skin; a little lens blur and sensor noise.
    #[default]
    Clean,
    /// As a mouth is really filmed: pink gums beyond the crowns, the tongue filling the
    /// bottom of the opening, wet highlights on enamel, lips and tongue, crowns shaded by
    /// the lips, and motion blur (the pictures are the mean over the shutter's poses).
    Hard,
}

/// One picture: `shutter` holds the poses the subject passes through while the shutter is
/// open (one for a still subject); the labels are those of the middle one.
#[allow(clippy::too_many_arguments)]
pub fn render_colour(
    cam: &Camera,
    meshes: [&Mesh; 2],
    shutter: &[ArchPoses],
    lips: &[LipLine; 2],
    show: [f64; 2],
    exposure: Exposure,
    photos: Photos,
    rng: &mut impl rand::Rng,
) -> ColourFrame {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let fields = Fields {
        texture: SmoothNoise::new(w, h, 9, rng),
        glints: SmoothNoise::new(w, h, 3, rng),
    };
    let mut linear = vec![[0f64; 3]; w * h];
    let mut labels = Vec::new();
    for (k, poses) in shutter.iter().enumerate() {
        let (colours, drawn) = draw(cam, meshes, poses, lips, show, photos, &fields);
        for (sum, c) in linear.iter_mut().zip(colours) {
            for j in 0..3 {
                sum[j] += decoded(c[j]) / shutter.len() as f64;
            }
        }
        if k == shutter.len() / 2 {
            labels = drawn;
        }
    }
    // A lens a little out of focus: [1 2 1] / 4 along rows, then columns.
    let linear = blur(&blur(&linear, w, h, 1), w, h, w);
    let rgb = expose(&linear, exposure, rng);
    ColourFrame { rgb, labels }
}

/// The random fields a picture's surfaces share over the shutter.
struct Fields {
    texture: SmoothNoise,
    /// Where wet surfaces catch the light.
    glints: SmoothNoise,
}

/// The colours (as the picture would show them, 0-255) and true labels of the subject at
/// one pose.
fn draw(
    cam: &Camera,
    meshes: [&Mesh; 2],
    poses: &ArchPoses,
    lips: &[LipLine; 2],
    show: [f64; 2],
    photos: Photos,
    fields: &Fields,
) -> (Vec<[f64; 3]>, Vec<u8>) {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let target = render_target(
        cam,
        &[
            (meshes[0], &poses.upper, UPPER_LABEL, UPPER_LABEL),
            (meshes[1], &poses.lower, LOWER_LABEL, LOWER_LABEL),
        ],
    );
    let opening = masks::lip_opening(cam, poses, lips, show);
    // The lips' height in pixels at the incisors' distance.
    let depth = cam
        .camera_from_world
        .compose(&poses.upper)
        .translation
        .z
        .max(1.0);
    let lip_px = cam.fx * LIP_HEIGHT_MM / depth;
    let shading = Shading {
        cam,
        target: &target,
        w,
        h,
        // Light from just above the lens (a ring light), in camera axes: towards the subject
        // is +z.
        to_light: Vector3::new(0.0, -0.35, -1.0).normalize(),
        wet: photos == Photos::Hard,
    };
    let soft = (photos == Photos::Hard)
        .then(|| SoftTissue::new(&target, &opening, w, h, cam.fx * GUM_MM / depth));
    let mut shown = vec![[0f64; 3]; w * h];
    let mut labels = vec![0u8; w * h];
    for y in 0..h {
        for (x, &(top, bottom)) in opening.iter().enumerate().take(w) {
            let i = y * w + x;
            let inside = (y as f64) > top && (y as f64) < bottom;
            let class = target.class[i];
            let t = fields.texture.at(x, y);
            let glint = 255.0 * ((fields.glints.at(x, y) - 0.8) / 0.2).max(0.0).powi(2);
            let colour = if inside && class != 0 {
                labels[i] = class;
                let crown = shading.crown(x, y, class, t);
                match &soft {
                    // Within a fifth of the lips' height of the opening's edge, the lip's
                    // shadow.
                    Some(_) => {
                        let edge = (y as f64 - top).min(bottom - y as f64);
                        let shade = 0.5 + 0.5 * (edge / (0.2 * lip_px)).min(1.0);
                        crown.map(|c| c * shade)
                    }
                    None => crown,
                }
            } else if inside {
                labels[i] = MOUTH_LABEL;
                match soft.as_ref().map(|s| s.at(x, y, top, bottom)) {
                    Some(Some(Tissue::Gum)) => GUM.map(|c| c * (1.0 + 0.1 * t)),
                    Some(Some(Tissue::Tongue)) => {
                        TONGUE.map(|c| c * (0.85 + 0.15 * t) + 0.6 * glint)
                    }
                    _ => mouth_colour(y, top, bottom, t),
                }
            } else {
                let face = face_colour(y, top, bottom, lip_px, t);
                let on_lip = (top - y as f64).max(y as f64 - bottom) < lip_px;
                if soft.is_some() && on_lip {
                    face.map(|c| c + 0.5 * glint)
                } else {
                    face
                }
            };
            shown[i] = colour;
        }
    }
    (shown, labels)
}

/// The soft tissue a hard picture shows inside the opening: gums just beyond the crowns
/// (above the upper's, below the lower's), the tongue filling the bottom of the opening
/// behind the lower teeth.
struct SoftTissue {
    /// Per column, the top row of the upper crowns and the bottom row of the lower crowns
    /// inside the opening.
    upper_top: Vec<f64>,
    lower_bottom: Vec<f64>,
    gum_px: f64,
    /// The opening's middle column and half its width.
    centre: f64,
    half_width: f64,
}

enum Tissue {
    Gum,
    Tongue,
}

impl SoftTissue {
    fn new(target: &Target, opening: &[(f64, f64)], w: usize, h: usize, gum_px: f64) -> Self {
        let mut upper_top = vec![f64::INFINITY; w];
        let mut lower_bottom = vec![f64::NEG_INFINITY; w];
        let (mut first, mut last) = (f64::INFINITY, f64::NEG_INFINITY);
        for (x, &(top, bottom)) in opening.iter().enumerate().take(w) {
            if top < bottom {
                first = first.min(x as f64);
                last = last.max(x as f64);
            }
            for y in 0..h {
                let yf = y as f64;
                if yf <= top || yf >= bottom {
                    continue;
                }
                match target.class[y * w + x] {
                    UPPER_LABEL => upper_top[x] = upper_top[x].min(yf),
                    LOWER_LABEL => lower_bottom[x] = lower_bottom[x].max(yf),
                    _ => {}
                }
            }
        }
        SoftTissue {
            upper_top,
            lower_bottom,
            gum_px,
            centre: 0.5 * (first + last),
            half_width: (0.5 * (last - first)).max(0.0),
        }
    }

    fn at(&self, x: usize, y: usize, top: f64, bottom: f64) -> Option<Tissue> {
        let yf = y as f64;
        let gum_above = self.upper_top[x] - yf;
        let gum_below = yf - self.lower_bottom[x];
        if (gum_above > 0.0 && gum_above <= self.gum_px)
            || (gum_below > 0.0 && gum_below <= self.gum_px)
        {
            return Some(Tissue::Gum);
        }
        let across = (x as f64 - self.centre) / (0.35 * self.half_width).max(1.0);
        let down = (yf - top) / (bottom - top).max(1.0);
        (across.abs() < 1.0 && down > 0.55 + 0.3 * across * across).then_some(Tissue::Tongue)
    }
}

/// What shading a crown's pixel needs: the camera, what it drew, and the light.
struct Shading<'a> {
    cam: &'a Camera,
    target: &'a Target,
    w: usize,
    h: usize,
    /// The unit direction towards the light, in camera axes.
    to_light: Vector3<f64>,
    /// Wet enamel: a sharper, brighter highlight.
    wet: bool,
}

impl Shading<'_> {
    /// The point (camera axes) drawn at pixel (x, y), if any.
    fn point(&self, x: usize, y: usize) -> Option<Vector3<f64>> {
        let inv_z = self.target.inv_depth[y * self.w + x] as f64;
        (inv_z > 0.0).then(|| {
            let z = 1.0 / inv_z;
            Vector3::new(
                (x as f64 - self.cam.cx) / self.cam.fx * z,
                (y as f64 - self.cam.cy) / self.cam.fy * z,
                z,
            )
        })
    }

    /// The unit normal, facing the camera, at pixel (x, y) showing point `p` of class `class`:
    /// from the neighbouring pixels of the same class.
    fn normal(&self, x: usize, y: usize, class: u8, p: Vector3<f64>) -> Vector3<f64> {
        let (w, h) = (self.w, self.h);
        let near = |dx: i64, dy: i64| {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            (nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h)
                .then_some((nx as usize, ny as usize))
                .filter(|&(nx, ny)| self.target.class[ny * w + nx] == class)
                .and_then(|(nx, ny)| self.point(nx, ny))
                .unwrap_or(p)
        };
        let du = near(1, 0) - near(-1, 0);
        let dv = near(0, 1) - near(0, -1);
        let mut n = du.cross(&dv);
        if n.norm() < 1e-12 {
            n = -p;
        }
        let mut n = n.normalize();
        if n.dot(&p) > 0.0 {
            n = -n;
        }
        n
    }

    /// A crown's colour at pixel (x, y) of class `class`, texture `t`: diffuse with a
    /// highlight.
    fn crown(&self, x: usize, y: usize, class: u8, t: f64) -> [f64; 3] {
        let p = self.point(x, y).expect("a drawn pixel has a depth");
        let n = self.normal(x, y, class, p);
        let diffuse = n.dot(&self.to_light).max(0.0);
        let half = (self.to_light - p.normalize()).normalize();
        let specular = if self.wet {
            1.2 * n.dot(&half).max(0.0).powi(80)
        } else {
            0.55 * n.dot(&half).max(0.0).powi(40)
        };
        TEETH.map(|c| c * (1.0 + 0.05 * t) * (0.35 + 0.65 * diffuse) + 255.0 * specular)
    }
}

/// The mouth interior's colour in row `y` of an opening from `top` to `bottom`, texture `t`:
/// darker towards the middle of the opening, where the throat is.
fn mouth_colour(y: usize, top: f64, bottom: f64, t: f64) -> [f64; 3] {
    let middle = ((y as f64 - top) / (bottom - top).max(1.0) - 0.5).abs() * 2.0;
    MOUTH.map(|c| c * (0.75 + 0.35 * middle) * (1.0 + 0.15 * t))
}

/// The colour outside the opening from `top` to `bottom` in row `y`, texture `t`: lip within
/// `lip_px` of the opening, skin beyond.
fn face_colour(y: usize, top: f64, bottom: f64, lip_px: f64, t: f64) -> [f64; 3] {
    let beyond = if top.is_finite() && bottom.is_finite() && top < bottom {
        (top - y as f64).max(y as f64 - bottom)
    } else {
        f64::INFINITY
    };
    if beyond < lip_px {
        LIP.map(|c| c * (1.0 + 0.08 * t))
    } else {
        SKIN.map(|c| c * (1.0 + 0.06 * t))
    }
}

/// The picture's bytes: the light under `exposure`, encoded as a camera writes it, with the
/// sensor's noise.
fn expose(linear: &[[f64; 3]], exposure: Exposure, rng: &mut impl rand::Rng) -> Vec<u8> {
    let mut rgb = vec![0u8; linear.len() * 3];
    for (i, colour) in linear.iter().enumerate() {
        for k in 0..3 {
            let noise = rng.random_range(-4.0..=4.0);
            let v = encoded(colour[k] * exposure.gain * exposure.white[k]) + noise;
            rgb[i * 3 + k] = v.round().clamp(0.0, 255.0) as u8;
        }
    }
    rgb
}

/// [1 2 1] / 4 between each pixel and its neighbours `step` apart (1: along rows, the
/// width: along columns), the border repeated.
fn blur(src: &[[f64; 3]], w: usize, h: usize, step: usize) -> Vec<[f64; 3]> {
    (0..src.len())
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (has_before, has_after) = if step == 1 {
                (x > 0, x + 1 < w)
            } else {
                (y > 0, y + 1 < h)
            };
            let before = if has_before { src[i - step] } else { src[i] };
            let after = if has_after { src[i + step] } else { src[i] };
            std::array::from_fn(|k| 0.25 * before[k] + 0.5 * src[i][k] + 0.25 * after[k])
        })
        .collect()
}

/// A smooth random field in [-1, 1]: a grid of values `cell` pixels apart, bilinear between.
struct SmoothNoise {
    grid: Vec<f64>,
    columns: usize,
    cell: usize,
}

impl SmoothNoise {
    fn new(w: usize, h: usize, cell: usize, rng: &mut impl rand::Rng) -> SmoothNoise {
        let columns = w / cell + 2;
        let rows = h / cell + 2;
        SmoothNoise {
            grid: (0..columns * rows)
                .map(|_| rng.random_range(-1.0..=1.0))
                .collect(),
            columns,
            cell,
        }
    }

    fn at(&self, x: usize, y: usize) -> f64 {
        let (fx, fy) = (x as f64 / self.cell as f64, y as f64 / self.cell as f64);
        let (ix, iy) = (fx as usize, fy as usize);
        let (tx, ty) = (fx - ix as f64, fy - iy as f64);
        let g = |i: usize, j: usize| self.grid[j * self.columns + i];
        (g(ix, iy) * (1.0 - tx) + g(ix + 1, iy) * tx) * (1.0 - ty)
            + (g(ix, iy + 1) * (1.0 - tx) + g(ix + 1, iy + 1) * tx) * ty
    }
}

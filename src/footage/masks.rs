//! Masks in from segmentation tools, written as the capture format's masks/<camera>/:
//!
//! - **Per-object binary PNGs**, as SAM 2's video predictor is commonly saved: a folder per
//!   object (`DIR/<object>/<frame>.png`), a pixel belonging to the object when it is not 0.
//! - **Colour-coded PNGs with a label map**, as CVAT's "Segmentation mask 1.1" export writes
//!   them: `DIR/labelmap.txt` (`name:r,g,b::` per line) and `DIR/SegmentationClass/<frame>.png`.
//!
//! Each source label is mapped to a class: the upper arch, the lower arch, teeth (both arches
//! as one, for the combined mode) or the visible mouth interior. Frame numbers are the digits
//! at the end of each file's stem (`frame_000012.png` is 12), plus an offset.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::read::read_text;
use crate::io::write_atomic;

/// The class a source label becomes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Class {
    Upper,
    Lower,
    Teeth,
    Mouth,
}

/// The pixel values written (those `jawtrack synth` writes): valid in either mask mode.
pub const UPPER_VALUE: u8 = 85;
pub const LOWER_VALUE: u8 = 170;
pub const TEETH_VALUE: u8 = 255;
pub const MOUTH_VALUE: u8 = 40;

impl Class {
    fn value(self) -> u8 {
        match self {
            Class::Upper => UPPER_VALUE,
            Class::Lower => LOWER_VALUE,
            Class::Teeth => TEETH_VALUE,
            Class::Mouth => MOUTH_VALUE,
        }
    }

    pub fn parse(s: &str) -> Option<Class> {
        Some(match s {
            "upper" => Class::Upper,
            "lower" => Class::Lower,
            "teeth" => Class::Teeth,
            "mouth" => Class::Mouth,
            _ => return None,
        })
    }
}

/// Where the masks come from.
#[derive(Debug, Clone)]
pub enum Source {
    /// A folder per object of binary PNGs.
    Objects(PathBuf),
    /// A CVAT "Segmentation mask 1.1" export: labelmap.txt and SegmentationClass/.
    Cvat(PathBuf),
}

/// What was written, for the user.
#[derive(Debug, Clone, Default)]
pub struct Imported {
    pub frames: usize,
    /// Pixels two classes claimed (left unlabelled: neither is sure).
    pub conflicts: u64,
    /// The capture.json `masks` block these masks need.
    pub masks_block: String,
}

/// The number at the end of a file stem.
fn frame_number(path: &Path) -> Option<i64> {
    let stem = path.file_stem()?.to_str()?;
    let digits: String = stem
        .chars()
        .rev()
        .take_while(|c| c.is_ascii_digit())
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    digits.parse().ok()
}

fn pngs(dir: &Path) -> Result<BTreeMap<i64, PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|error| Error::Read {
        path: dir.to_path_buf(),
        error,
    })?;
    let mut out = BTreeMap::new();
    for e in rd.flatten() {
        let p = e.path();
        if p.extension()
            .and_then(|x| x.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
            != Some("png")
        {
            continue;
        }
        let Some(n) = frame_number(&p) else {
            return Err(Error::invalid(
                &p,
                "file name",
                "has no frame number at the end of its name",
            ));
        };
        if let Some(other) = out.insert(n, p.clone()) {
            return Err(Error::invalid(
                &p,
                "file name",
                format!("frame {n} again (also {})", other.display()),
            ));
        }
    }
    Ok(out)
}

fn open_image(path: &Path) -> Result<image::DynamicImage> {
    let (w, h) = image::image_dimensions(path).map_err(|e| Error::Image {
        path: path.to_path_buf(),
        problem: e.to_string(),
    })?;
    // 8K video is 33 Mpx; a header claiming more is not a frame's mask.
    if w as u64 * h as u64 > 1 << 26 {
        return Err(Error::invalid(
            path,
            "size",
            format!("{w}x{h} is beyond 67 Mpx: not a video frame's mask"),
        ));
    }
    image::open(path).map_err(|e| Error::Image {
        path: path.to_path_buf(),
        problem: e.to_string(),
    })
}

/// An object mask's pixels that belong to the object: any value but 0 in any colour channel
/// (a 16-bit mask of 0/1 too, which 8 bits would round to 0), where the pixel is not fully
/// transparent.
fn object_pixels(img: &image::DynamicImage) -> Vec<bool> {
    img.to_rgba16()
        .pixels()
        .map(|p| p.0[3] != 0 && (p.0[0] | p.0[1] | p.0[2]) != 0)
        .collect()
}

/// The CVAT label map: name → colour.
fn read_labelmap(path: &Path) -> Result<BTreeMap<String, [u8; 3]>> {
    let text = read_text(path, "CVAT label map")?;
    let mut out = BTreeMap::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let field = format!("line {}", i + 1);
        let mut parts = line.split(':');
        let (Some(name), Some(colour)) = (parts.next(), parts.next()) else {
            return Err(Error::invalid(
                path,
                &field,
                "expected name:r,g,b:parts:actions",
            ));
        };
        let c: Vec<u8> = colour
            .split(',')
            .map(|v| v.trim().parse::<u8>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| {
                Error::invalid(path, &field, format!("`{colour}` is not r,g,b (0-255)"))
            })?;
        let [r, g, b] = c[..] else {
            return Err(Error::invalid(
                path,
                &field,
                format!("`{colour}` is not r,g,b"),
            ));
        };
        if out.contains_key(name) {
            return Err(Error::invalid(
                path,
                &field,
                format!("label `{name}` is listed twice: each label once, with one colour"),
            ));
        }
        if let Some((other, _)) = out.iter().find(|(_, c)| **c == [r, g, b]) {
            return Err(Error::invalid(
                path,
                &field,
                format!(
                    "`{name}` has the colour of `{other}` ({r},{g},{b}): the pixels could not be told apart"
                ),
            ));
        }
        out.insert(name.to_string(), [r, g, b]);
    }
    Ok(out)
}

/// Per source frame number, each file with the class its pixels become.
type SourceFrames = BTreeMap<i64, Vec<(Class, PathBuf)>>;
/// A CVAT label map: each colour and the class it paints.
type ColourClasses = Vec<([u8; 3], Class)>;

/// Write masks/<camera>/<frame:06>.png under `capture` from `source`, each source label in
/// `labels` (label → class) becoming its class's value. Refuses to write into a folder that
/// holds masks unless `replace`.
pub fn import_masks(
    capture: &Path,
    camera: &str,
    source: &Source,
    labels: &[(String, Class)],
    frame_offset: i64,
    replace: bool,
) -> Result<Imported> {
    let classes: Vec<Class> = labels.iter().map(|l| l.1).collect();
    check_classes(capture, &classes)?;
    let out_dir = capture.join("masks").join(camera);
    check_output(&out_dir, replace)?;
    // Per frame, per class, the source image's pixels that belong to it.
    let (frames, colours) = match source {
        Source::Objects(dir) => (object_frames(dir, labels)?, None),
        Source::Cvat(dir) => {
            let (frames, colours) = cvat_frames(dir, labels)?;
            (frames, Some(colours))
        }
    };
    if frames.is_empty() {
        return Err(Error::invalid(
            capture,
            "masks",
            "the source holds no PNG frames",
        ));
    }
    let mut imported = Imported::default();
    for (n, files) in &frames {
        imported.conflicts += write_frame(&out_dir, *n, files, frame_offset, colours.as_deref())?;
        imported.frames += 1;
    }
    imported.masks_block = masks_block(&classes);
    Ok(imported)
}

/// Refuses labels that mix the combined and per-arch modes, or that name no teeth at all.
fn check_classes(capture: &Path, classes: &[Class]) -> Result<()> {
    let has = |c: Class| classes.contains(&c);
    if has(Class::Teeth) && (has(Class::Upper) || has(Class::Lower)) {
        return Err(Error::invalid(
            capture,
            "labels",
            "teeth (combined) and upper/lower (per arch) cannot be mixed",
        ));
    }
    if !(has(Class::Teeth) || has(Class::Upper) || has(Class::Lower)) {
        return Err(Error::invalid(
            capture,
            "labels",
            "no label is mapped to teeth, upper or lower",
        ));
    }
    Ok(())
}

/// Refuses an output folder that holds anything already, unless `replace`.
fn check_output(out_dir: &Path, replace: bool) -> Result<()> {
    if !replace
        && out_dir.is_dir()
        && std::fs::read_dir(out_dir)
            .map(|mut d| d.next().is_some())
            .unwrap_or(false)
    {
        return Err(Error::invalid(
            out_dir,
            "output",
            "holds masks already: pass --replace to overwrite them",
        ));
    }
    Ok(())
}

/// The frames of a folder per object: each object's PNGs, as its class.
fn object_frames(dir: &Path, labels: &[(String, Class)]) -> Result<SourceFrames> {
    let mut frames = SourceFrames::new();
    for (object, class) in labels {
        let sub = dir.join(object);
        if !sub.is_dir() {
            return Err(Error::Missing {
                path: sub,
                what: format!("object folder `{object}`"),
            });
        }
        for (n, p) in pngs(&sub)? {
            frames.entry(n).or_default().push((*class, p));
        }
    }
    Ok(frames)
}

/// The frames of a CVAT export, and the colour each label's pixels have in them.
fn cvat_frames(dir: &Path, labels: &[(String, Class)]) -> Result<(SourceFrames, ColourClasses)> {
    let map = read_labelmap(&dir.join("labelmap.txt"))?;
    let mut colours = Vec::new();
    for (name, class) in labels {
        let c = map.get(name).ok_or_else(|| {
            Error::invalid(
                dir.join("labelmap.txt"),
                name,
                format!(
                    "no such label; the map has {}",
                    map.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        colours.push((*c, *class));
    }
    // One file a frame; each pixel's class comes from its colour.
    let mut frames = SourceFrames::new();
    for (n, p) in pngs(&dir.join("SegmentationClass"))? {
        frames.entry(n).or_default().push((Class::Teeth, p));
    }
    Ok((frames, colours))
}

/// Paints source frame `n` from its files and writes it as capture frame `n + frame_offset`;
/// returns how many pixels two classes claimed. `colours` is the CVAT label colours, `None`
/// for object masks.
fn write_frame(
    out_dir: &Path,
    n: i64,
    files: &[(Class, PathBuf)],
    frame_offset: i64,
    colours: Option<&[([u8; 3], Class)]>,
) -> Result<u64> {
    let frame = n + frame_offset;
    let Ok(frame) = u32::try_from(frame) else {
        return Err(Error::invalid(
            &files[0].1,
            "frame",
            format!("frame {n} + offset {frame_offset} is negative"),
        ));
    };
    let mut mask = FrameMask::new(n);
    for (class, path) in files {
        let img = open_image(path)?;
        let (w, h) = (img.width(), img.height());
        match colours {
            None => {
                let on = object_pixels(&img);
                mask.paint(path, w, h, &|i| on[i].then_some(*class))?;
            }
            Some(colours) => {
                let rgb = img.into_rgb8();
                let raw = rgb.as_raw();
                mask.paint(path, w, h, &|i| {
                    let px = [raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]];
                    colours
                        .iter()
                        .find(|(c, _)| *c == px)
                        .map(|(_, class)| *class)
                })?;
            }
        }
    }
    let (w, h) = mask.size.expect("a frame has a file");
    let png = crate::io::encode_png(&mask.out, w, h, image::ExtendedColorType::L8);
    write_atomic(&out_dir.join(format!("{frame:06}.png")), &png)?;
    Ok(mask.conflicts)
}

/// One frame's mask as it is painted from its source files.
struct FrameMask {
    /// The source frame number, for messages.
    n: i64,
    /// The frame's size, fixed by its first file.
    size: Option<(u32, u32)>,
    out: Vec<u8>,
    /// Per pixel: 0 unclaimed, 1 claimed by one class, 2 claimed by two (left unlabelled).
    claimed: Vec<u8>,
    /// Pixels two classes claimed.
    conflicts: u64,
}

impl FrameMask {
    /// An empty mask for source frame `n`, sized by the first file painted.
    fn new(n: i64) -> Self {
        FrameMask {
            n,
            size: None,
            out: Vec::new(),
            claimed: Vec::new(),
            conflicts: 0,
        }
    }

    /// Paints a `w`×`h` file's pixels of a class (`pixel` gives each pixel's, if any) onto
    /// the mask; refuses a file the size of none of the frame's others.
    fn paint(
        &mut self,
        path: &Path,
        w: u32,
        h: u32,
        pixel: &dyn Fn(usize) -> Option<Class>,
    ) -> Result<()> {
        match self.size {
            None => {
                self.size = Some((w, h));
                self.out = vec![0; (w * h) as usize];
                self.claimed = vec![0; (w * h) as usize];
            }
            Some(s) if s != (w, h) => {
                let n = self.n;
                return Err(Error::invalid(
                    path,
                    "size",
                    format!("{w}x{h}, but frame {n}'s other masks are {}x{}", s.0, s.1),
                ));
            }
            _ => {}
        }
        for i in 0..self.out.len() {
            if let Some(class) = pixel(i) {
                self.claim(i, class);
            }
        }
        Ok(())
    }

    /// Gives pixel `i` to `class`, settling a pixel another class holds already.
    fn claim(&mut self, i: usize, class: Class) {
        let v = class.value();
        match self.claimed[i] {
            0 => {
                self.claimed[i] = 1;
                self.out[i] = v;
            }
            _ if self.out[i] == v => {}
            // Teeth over the mouth interior (a tooth's edge seen inside the lips);
            // two arches on one pixel: neither.
            _ if class == Class::Mouth => {}
            _ if self.out[i] == MOUTH_VALUE => self.out[i] = v,
            _ => {
                if self.claimed[i] == 1 {
                    self.conflicts += 1;
                }
                self.claimed[i] = 2;
                self.out[i] = 0;
            }
        }
    }
}

/// The capture.json `masks` block for masks of these classes.
fn masks_block(classes: &[Class]) -> String {
    let has = |c: Class| classes.contains(&c);
    let mouth = if has(Class::Mouth) {
        format!(", \"mouth\": {MOUTH_VALUE}")
    } else {
        String::new()
    };
    if has(Class::Teeth) {
        format!("\"masks\": {{\"dir\": \"masks\", \"mode\": \"combined\"{mouth}}}")
    } else {
        format!(
            "\"masks\": {{\"dir\": \"masks\", \"mode\": \"per-arch\", \"upper\": {UPPER_VALUE}, \"lower\": {LOWER_VALUE}{mouth}}}"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_numbers_come_from_the_end_of_the_name() {
        assert_eq!(frame_number(Path::new("frame_000012.png")), Some(12));
        assert_eq!(frame_number(Path::new("00007.png")), Some(7));
        assert_eq!(frame_number(Path::new("mask.png")), None);
    }
}

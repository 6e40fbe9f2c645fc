//! Video in: frames of any video ffmpeg reads, written as images/<camera>/<frame:06>.png (or
//! .jpg) by the `ffmpeg` program, run as a process. File numbers are the video's own frame
//! numbers (decoded order, from 0), so a cut range keeps its place in the footage and the
//! sync offsets stay valid.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::error::{Error, Result};

/// Where ffmpeg is found: `JAWTRACK_FFMPEG` names the program, else `ffmpeg` on the PATH.
pub fn ffmpeg_program() -> PathBuf {
    std::env::var_os("JAWTRACK_FFMPEG")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("ffmpeg"))
}

/// ffprobe beside ffmpeg (the same folder when ffmpeg is named by path).
fn ffprobe_program() -> PathBuf {
    let ff = ffmpeg_program();
    match ff.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join("ffprobe"),
        _ => PathBuf::from("ffprobe"),
    }
}

const INSTALL: &str = "install it from the system's packages (`apt-get install ffmpeg` on \
                       Debian/Ubuntu, `dnf install ffmpeg` on Fedora, `brew install ffmpeg` on \
                       macOS) or name it with JAWTRACK_FFMPEG=/path/to/ffmpeg";

fn spawn_error(program: &Path, video: &Path, e: std::io::Error) -> Error {
    let problem = if e.kind() == std::io::ErrorKind::NotFound {
        format!(
            "the `{}` program was not found: {INSTALL}",
            program.display()
        )
    } else {
        format!("cannot run `{}`: {e}", program.display())
    };
    Error::invalid(video, "ffmpeg", problem)
}

/// The image format frames are written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrameFormat {
    /// Lossless.
    #[default]
    Png,
    /// About a tenth of the size, at ffmpeg's quality 2 (of 2-31).
    Jpg,
}

impl FrameFormat {
    pub fn extension(self) -> &'static str {
        match self {
            FrameFormat::Png => "png",
            FrameFormat::Jpg => "jpg",
        }
    }
}

/// What ffprobe says of a video's first video stream.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoInfo {
    pub width: u32,
    pub height: u32,
    /// Frames per second, when the container states it.
    pub fps: Option<f64>,
    /// Frame count, when the container states it (MP4 and MOV do).
    pub frames: Option<u64>,
}

#[derive(serde::Deserialize)]
struct Probe {
    #[serde(default)]
    streams: Vec<ProbeStream>,
}

#[derive(serde::Deserialize)]
struct ProbeStream {
    width: Option<u32>,
    height: Option<u32>,
    avg_frame_rate: Option<String>,
    nb_frames: Option<String>,
}

/// `path` as ffmpeg must read it: `file:` and the absolute path, so that a name such as
/// `-report` is not taken as an option, nor `concat:a.mp4` as a protocol.
fn input_url(path: &Path) -> Result<std::ffi::OsString> {
    let absolute = std::path::absolute(path).map_err(|error| Error::Read {
        path: path.to_path_buf(),
        error,
    })?;
    let mut url = std::ffi::OsString::from("file:");
    url.push(absolute.as_os_str());
    Ok(url)
}

/// The highest frame number the capture's file names hold (`<frame:06>`).
pub const MAX_FRAME: u64 = 999_999;

/// Probe a video with ffprobe.
pub fn probe(video: &Path) -> Result<VideoInfo> {
    if !video.is_file() {
        return Err(Error::Missing {
            path: video.to_path_buf(),
            what: "video".into(),
        });
    }
    let program = ffprobe_program();
    let input = input_url(video)?;
    let out = Command::new(&program)
        .args(["-v", "error", "-select_streams", "v:0", "-show_entries"])
        .arg("stream=width,height,avg_frame_rate,nb_frames")
        .args(["-of", "json"])
        .arg("-i")
        .arg(input)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| spawn_error(&program, video, e))?;
    if !out.status.success() {
        return Err(Error::invalid(
            video,
            "video",
            format!(
                "ffprobe cannot read it: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ),
        ));
    }
    let p: Probe = serde_json::from_slice(&out.stdout).map_err(|e| {
        Error::invalid(
            video,
            "video",
            format!("ffprobe's answer did not parse: {e}"),
        )
    })?;
    let s = p
        .streams
        .into_iter()
        .next()
        .ok_or_else(|| Error::invalid(video, "video", "has no video stream"))?;
    let (Some(width), Some(height)) = (s.width, s.height) else {
        return Err(Error::invalid(
            video,
            "video",
            "ffprobe gives no frame size",
        ));
    };
    let fps = s.avg_frame_rate.as_deref().and_then(|r| {
        let (n, d) = r.split_once('/')?;
        let (n, d): (f64, f64) = (n.parse().ok()?, d.parse().ok()?);
        (d > 0.0 && n > 0.0).then_some(n / d)
    });
    let frames = s
        .nb_frames
        .as_deref()
        .and_then(|n| n.parse().ok())
        .filter(|&n| n > 0);
    Ok(VideoInfo {
        width,
        height,
        fps,
        frames,
    })
}

/// Which frames to write and how.
#[derive(Debug, Clone, Copy, Default)]
pub struct Extract {
    /// The first frame written (the video's frame number, from 0).
    pub first: u64,
    /// How many frames at most (all to the end when `None`).
    pub count: Option<u64>,
    pub format: FrameFormat,
    /// Replace an existing images/<camera>/ folder (otherwise one is never touched).
    pub replace: bool,
}

/// ffmpeg before 5.1 knows `-vsync`, after it `-fps_mode`; both keep every decoded frame
/// once (no duplicates to fill a constant rate).
fn passthrough_args(program: &Path) -> [&'static str; 2] {
    let version = Command::new(program)
        .arg("-version")
        .stdin(Stdio::null())
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    let number = version.split_whitespace().nth(2).and_then(|v| {
        let mut it = v.split(['.', '-']);
        Some((
            it.next()?.parse::<u32>().ok()?,
            it.next()?.parse::<u32>().ok()?,
        ))
    });
    match number {
        Some((major, minor)) if (major, minor) < (5, 1) => ["-vsync", "passthrough"],
        _ => ["-fps_mode", "passthrough"],
    }
}

/// Write frames of `video` to `out` (e.g. capture/images/cam0) through a staging folder
/// beside it, renamed into place when ffmpeg has finished, so an interrupted import leaves no
/// half-filled folder. `progress` is called with the number of frames written so far.
/// Returns the number of frames written.
pub fn extract(
    video: &Path,
    out: &Path,
    options: &Extract,
    mut progress: impl FnMut(u64),
) -> Result<u64> {
    check_extract(video, out, options)?;
    let parent = out.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|e| write_error(parent, e))?;
    let stage = tempfile::Builder::new()
        .prefix(".import-")
        .tempdir_in(parent)
        .map_err(|e| write_error(parent, e))?;

    let program = ffmpeg_program();
    let input = input_url(video)?;
    // The stage's path is absolute, so it is never read as an option either.
    let pattern = std::path::absolute(stage.path())
        .map_err(|e| write_error(stage.path(), e))?
        .join(format!("%06d.{}", options.format.extension()));
    let cmd = ffmpeg_command(&program, input, pattern, options);
    run_ffmpeg(cmd, &program, video, &mut progress)?;
    let written = count_written(stage.path(), video, options.first)?;
    progress(written);
    // The stage is removed with `stage` if a rename fails; once renamed, it is the output.
    move_into_place(stage.path(), out, parent)?;
    let _ = stage.keep();
    Ok(written)
}

/// The error of a failed write at `path`.
fn write_error(path: &Path, error: std::io::Error) -> Error {
    Error::Write {
        path: path.to_path_buf(),
        error,
    }
}

/// Refuses a missing video, frames beyond the capture's numbers, and an output that is a
/// link or exists without `replace`.
fn check_extract(video: &Path, out: &Path, options: &Extract) -> Result<()> {
    if !video.is_file() {
        return Err(Error::Missing {
            path: video.to_path_buf(),
            what: "video".into(),
        });
    }
    if options.first > MAX_FRAME
        || options
            .count
            .is_some_and(|n| n == 0 || n > MAX_FRAME + 1 - options.first)
    {
        return Err(Error::invalid(
            video,
            "--first/--count",
            format!(
                "frames {} on ({}): the capture's frame numbers run from 0 to {MAX_FRAME}",
                options.first,
                options
                    .count
                    .map_or("to the end".to_string(), |n| format!("{n} of them")),
            ),
        ));
    }
    if out
        .symlink_metadata()
        .is_ok_and(|m| m.file_type().is_symlink())
    {
        return Err(Error::invalid(
            out,
            "output",
            "is a link: the frames are written into a folder of the capture itself; remove the link",
        ));
    }
    if out.exists() && !options.replace {
        return Err(Error::invalid(
            out,
            "output",
            "exists: remove it, or pass --replace to write the frames anew",
        ));
    }
    Ok(())
}

/// The ffmpeg command writing the chosen frames of `input` to the numbered files `pattern`,
/// reporting its progress on stdout.
fn ffmpeg_command(
    program: &Path,
    input: std::ffi::OsString,
    pattern: PathBuf,
    options: &Extract,
) -> Command {
    let mut cmd = Command::new(program);
    cmd.args(["-nostdin", "-hide_banner", "-loglevel", "error", "-nostats"])
        .args(["-progress", "pipe:1"])
        .arg("-i")
        .arg(input)
        .args(["-map", "0:v:0"])
        .args(passthrough_args(program));
    if options.first > 0 {
        cmd.args(["-vf", &format!("select=gte(n\\,{})", options.first)]);
    }
    if let Some(n) = options.count {
        cmd.args(["-frames:v", &n.to_string()]);
    }
    if options.format == FrameFormat::Jpg {
        cmd.args(["-q:v", "2"]);
    }
    cmd.args(["-start_number", &options.first.to_string(), "-f", "image2"])
        .arg(pattern)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    cmd
}

/// Runs ffmpeg to the end, passing on the frame counts it reports; its error output becomes
/// the error when it fails.
fn run_ffmpeg(
    mut cmd: Command,
    program: &Path,
    video: &Path,
    progress: &mut impl FnMut(u64),
) -> Result<()> {
    let mut child = cmd.spawn().map_err(|e| spawn_error(program, video, e))?;
    let mut stderr = child.stderr.take().expect("piped");
    let errors = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let stdout = child.stdout.take().expect("piped");
    for line in BufReader::new(stdout).lines().map_while(|l| l.ok()) {
        if let Some(n) = line
            .strip_prefix("frame=")
            .and_then(|n| n.trim().parse().ok())
        {
            progress(n);
        }
    }
    let status = child.wait().map_err(|e| spawn_error(program, video, e))?;
    let errors = errors.join().unwrap_or_default();
    if !status.success() {
        return Err(Error::invalid(
            video,
            "video",
            format!("ffmpeg failed ({status}): {}", errors.trim()),
        ));
    }
    Ok(())
}

/// How many frames ffmpeg wrote into `stage`; none is an error (the video ends before
/// `first`).
fn count_written(stage: &Path, video: &Path, first: u64) -> Result<u64> {
    let written = std::fs::read_dir(stage)
        .map_err(|e| Error::Read {
            path: stage.to_path_buf(),
            error: e,
        })?
        .count() as u64;
    if written == 0 {
        return Err(Error::invalid(
            video,
            "video",
            format!("no frames from frame {first} on: the video has fewer frames"),
        ));
    }
    Ok(written)
}

/// Renames the filled `stage` to `out`, replacing what was there only once the new frames
/// are in place (and putting it back if they cannot be).
fn move_into_place(stage: &Path, out: &Path, parent: &Path) -> Result<()> {
    if out.exists() {
        let old = parent.join(format!(
            ".replaced-{}",
            out.file_name().unwrap_or_default().to_string_lossy()
        ));
        std::fs::rename(out, &old).map_err(|e| write_error(out, e))?;
        if let Err(e) = std::fs::rename(stage, out) {
            // Put the frames that were there back.
            let _ = std::fs::rename(&old, out);
            return Err(write_error(out, e));
        }
        std::fs::remove_dir_all(&old).map_err(|e| write_error(&old, e))?;
    } else {
        std::fs::rename(stage, out).map_err(|e| write_error(out, e))?;
    }
    Ok(())
}

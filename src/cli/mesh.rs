use std::path::PathBuf;

use anyhow::{Context, bail};
use jawtrack::anatomy::scan_frame::scan_frame;
use jawtrack::mesh::{BoiMarking, mark_boi, write_obj};
use jawtrack::mesh::{BoiSource, Mesh};

#[derive(clap::Subcommand)]
pub enum Command {
    /// Mark the boundary of interest (incisal band of the front teeth, canine to canine) and
    /// write an OBJ with a `boi` group.
    Boi(BoiArgs),
}

#[derive(clap::Args)]
pub struct BoiArgs {
    /// Input mesh (OBJ, STL or PLY) in the scan frame: y up, +z anterior, millimetres.
    pub input: PathBuf,
    /// Output OBJ.
    pub output: PathBuf,
    /// Which arch (crowns point to −y for upper, +y for lower); guessed from the file name.
    #[arg(long, value_parser = ["upper", "lower"])]
    pub arch: Option<String>,
    /// Depth of the band from the incisal edge (mm).
    #[arg(long, value_parser = crate::cli::args::number_in(0.01, 100.0))]
    pub band_mm: Option<f64>,
    /// Share of each half-arch (by arc length from the midline) that counts as front teeth.
    #[arg(long, value_parser = crate::cli::args::number_in(0.01, 1.0))]
    pub front_fraction: Option<f64>,
    /// Simplify to at most this many triangles before writing.
    #[arg(long, value_parser = crate::cli::args::count_in(4, 100_000_000))]
    pub max_triangles: Option<usize>,
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Boi(a) => boi(a),
    }
}

fn boi(a: BoiArgs) -> anyhow::Result<()> {
    let upper = match a.arch.as_deref() {
        Some(arch) => arch == "upper",
        None => {
            let name = a
                .input
                .file_name()
                .map(|n| n.to_string_lossy().to_lowercase())
                .unwrap_or_default();
            match (name.contains("upper"), name.contains("lower")) {
                (true, false) => true,
                (false, true) => false,
                _ => bail!(
                    "{}: cannot tell the arch from the file name; pass --arch upper or --arch lower",
                    a.input.display()
                ),
            }
        }
    };
    let mut mesh = Mesh::load(&a.input, BoiSource::None).context("reading the mesh")?;
    let mut marking = BoiMarking::for_arch(upper);
    if let Some(b) = a.band_mm {
        marking.band_mm = b;
    }
    if let Some(f) = a.front_fraction {
        marking.front_fraction = f;
    }
    // The marking works in the scan frame; a scan written in another is refused rather than
    // marked in the wrong place.
    let found = scan_frame(&mesh, &nalgebra::Vector3::y());
    if found != nalgebra::Rotation3::identity() {
        let names = ["x", "y", "z"];
        let line = |v: nalgebra::Vector3<f64>| names[v.iamax()];
        let axis = |v: nalgebra::Vector3<f64>| {
            let k = v.iamax();
            format!("{}{}", if v[k] < 0.0 { "-" } else { "+" }, names[k])
        };
        let rows = found.matrix();
        bail!(
            "{}: not in the scan frame (y up, +z anterior): the arch's thinnest axis lies along {} and its front towards {}; turn the scan into the scan frame, or mark the boundary of interest as an OBJ group",
            a.input.display(),
            line(rows.row(1).transpose()),
            axis(rows.row(2).transpose())
        );
    }
    let n = mark_boi(&mut mesh, &marking);
    if n == 0 {
        bail!(
            "{}: no face was marked; is the mesh in the scan frame (y up, +z anterior)?",
            a.input.display()
        );
    }
    if let Some(max) = a.max_triangles {
        mesh = mesh.simplified(jawtrack::mesh::Simplify::MaxTriangles(max));
    }
    write_obj(&mesh, &a.output).context("writing the mesh")?;
    println!(
        "{}: {} of {} triangles marked as boundary of interest ({} arch) -> {}",
        a.input.display(),
        mesh.boi_face_count(),
        mesh.triangles.len(),
        if upper { "upper" } else { "lower" },
        a.output.display()
    );
    Ok(())
}

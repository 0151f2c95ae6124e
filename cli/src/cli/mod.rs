//! Argument parsing and command dispatch for the `scode` binary.

/// `println!` for the subcommands, which does not panic when stdout is a closed pipe
/// (`scode info --groups big.scode | head`): the rest of the output is dropped and the
/// command finishes its work (an encode still writes its file). Defined before the modules
/// so that it shadows std's macro in them.
macro_rules! println {
    ($($arg:tt)*) => {
        $crate::cli::print_line(format_args!($($arg)*))
    };
}

mod commands;
pub mod exit;
mod view;

/// Writes one line to stdout; a closed pipe is not an error (see `println!` above), any
/// other write error panics as std's `println!` does.
pub(crate) fn print_line(args: std::fmt::Arguments) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.write_all(b"\n")) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            panic!("failed printing to stdout: {e}");
        }
    }
}

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::{Args, Parser, Subcommand};

use exit::CliError;
use scode::codec::Limits;
use scode::io::MeshFormat;
use scode::pipeline::Effort;
use scode::Tolerance;

/// scode: a subdivision-surface codec for CAD models.
///
/// scode stores a CAD model as a small control mesh (one patch per CAD face, sharp edges on
/// face boundaries, corners at B-rep vertices) in a compact, checksummed `.scode` file, and
/// rebuilds the smooth, sharp-edged surface at any level of detail when decoding.
///
/// Mesh files are read and written by extension: .obj .ply .stl .glb .gltf (read) .off (read).
#[derive(Parser, Debug)]
#[command(
    name = "scode",
    version,
    about,
    long_about,
    propagate_version = true,
    after_help = exit::HELP
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Compress a mesh or a STEP file into a .scode file.
    ///
    /// By default the model is fitted: every CAD face (OBJ group, PLY face id, glTF
    /// primitive; an ungrouped mesh is segmented first) becomes a subdivision patch, and the
    /// coarse control mesh is stored. The encoder measures the decoded surface against the
    /// input and adds control points until --tolerance holds, then tries taking some back
    /// from faces that ended far within it (the smaller file wins); a face no smooth patch
    /// gets within the tolerance of is stored as its input facets. The encoder samples the
    /// decoded surface and the input as `scode info --against` does (every decoded vertex,
    /// the same random points, edge points at least as dense), so the error it prints is the
    /// written file's. A `<name>.faces.json` sidecar next to the input (as in the corpus)
    /// supplies each face's surface type.
    ///
    /// A STEP file (.step .stp) is read as a B-rep: each face is tessellated (one vertex
    /// pool, B-rep edges as sharp chains, B-rep vertices as corners) at a fraction of the
    /// tolerance, its surface type decides the patch kind, and faces on planes, cylinders,
    /// cones, spheres and tori are fitted onto their exact surfaces and held to the
    /// tolerance of them; the other faces, and decoded points beyond a face's outline, are
    /// held to it as the facets' distance plus their chordal tolerance, so the printed error
    /// bounds the distance to the B-rep. The file is tessellated once (analytic faces more coarsely,
    /// since their exact surfaces are the reference); --effort max fits five
    /// tessellations and keeps the smallest file (--verbose says which). Faces the
    /// reader cannot handle are named; the file is only encoded without them with
    /// --allow-skipped (else exit status 6). `scode info part.step` shows the plan.
    ///
    /// A decoded surface that misses --tolerance (or --mean-tolerance) is still written,
    /// and scode exits with status 5.
    ///
    /// With --raw the input mesh itself is stored as the control mesh (no fitting): a
    /// Draco-class lossy-by-quantisation coder. Faces keep their degree (quads and n-gons are
    /// not triangulated), OBJ groups, `l` sharp edges and corner tags are kept.
    ///
    /// Examples: scode encode part.obj part.scode
    ///           scode encode --tolerance 0.002 --relative part.obj -o part.scode
    ///           scode encode --raw part.obj part.scode
    ///           scode encode --verbose part.step part.scode
    #[command(verbatim_doc_comment)]
    Encode(EncodeArgs),
    /// Decompress a .scode file into a mesh (format chosen by the output extension).
    ///
    /// A raw-mode file decodes to the stored mesh. A control-mesh file is decoded to an
    /// accuracy: each triangle of the control mesh is subdivided to the coarsest level whose
    /// output lies within the tolerance of the surface the file describes (its limit
    /// surface), so flat and gently curved faces take few triangles and tight fillets more;
    /// neighbouring faces at different levels are stitched without cracks, and planes and
    /// cylinder/cone belts come out as few triangles. The tolerance is --tolerance, else the
    /// one the file was encoded for (files do not store it: 1e-3 of the diagonal, the
    /// encoder's default, but no more than the file's quantisation grid allows).
    /// --level N subdivides every face uniformly to level N instead.
    ///
    /// glTF output (.glb, .gltf) is laid out for CAD viewers: one triangle primitive per body
    /// (connected part) with the CAD face as a per-vertex feature id (_FEATURE_ID_0,
    /// EXT_mesh_features; face names in an EXT_structural_metadata property table) and the
    /// sharp edges as a line primitive; scode reads the faces back from it.
    ///
    /// Examples: scode decode part.scode part.obj
    ///           scode decode --tolerance 0.05 part.scode coarse.stl
    ///           scode decode --tolerance 2e-4 --relative part.scode fine.obj
    ///           scode decode --level 4 part.scode uniform.obj
    ///           scode decode --quantize part.scode part.glb
    #[command(verbatim_doc_comment)]
    Decode(DecodeArgs),
    /// Describe a .scode file (header, where the bits go) or a mesh file (what the reader saw).
    ///
    /// Example: scode info part.scode
    #[command(verbatim_doc_comment)]
    Info(InfoArgs),
    /// Subdivide a control mesh (any readable mesh file; OBJ `l` elements are sharp edges).
    ///
    /// Example: scode subdivide control.obj --level 3 -o smooth.obj
    #[command(verbatim_doc_comment)]
    Subdivide(SubdivideArgs),
    /// Split a mesh without groups into CAD-face-like regions (planes, cylinders, cones,
    /// spheres, tori, freeform) and write them as groups, so a person can look at them.
    ///
    /// Example: scode segment part.stl -o faces.obj
    #[command(verbatim_doc_comment)]
    Segment(SegmentArgs),
    /// Show a .scode file in the browser: serves the WebGL viewer and the file on localhost
    /// and prints the URL (opens it unless --no-open). The viewer decodes and subdivides in
    /// WebAssembly and picks the level of each base triangle from its size on screen.
    /// Serves until Ctrl-C.
    ///
    /// Example: scode view part.scode --port 8765
    #[command(verbatim_doc_comment)]
    View(ViewArgs),
    /// Compare scode with Draco and gltfpack at equal error on a set of models: tables and plots.
    ///
    /// For every model (OBJ/PLY/STL/glTF/OFF and STEP files) runs scode fitted at
    /// tolerances 4e-3 down to 5e-5 of the diagonal, scode raw at 10 bits (mesh files),
    /// Draco (draco_encoder/draco_decoder, -qp 6..16 at -cl 10 and 7) and gltfpack
    /// (meshoptimizer, -vp 8..16 with -cc), decodes every output and measures bytes, bits
    /// per vertex, max (Hausdorff) and RMS error, and encode/decode times. A mesh file is
    /// measured against itself. A STEP file is measured against its exact B-rep surfaces
    /// (--reference): scode encodes the STEP file, the baselines get the part tessellated
    /// at chordal tolerances 2e-3 down to 2.5e-5 of the diagonal, each at the three
    /// quantisation bit counts around that tolerance.
    /// For each scode point and each baseline, the smallest file with no larger max and RMS
    /// error gives the ratio baseline bytes / scode bytes; the headline is the best
    /// baseline's.
    ///
    /// Writes OUT/report.md (summary table first), OUT/results.csv, OUT/plots/*.png|svg and
    /// the encoded files under OUT/files/. Each scode encode runs in a child process killed
    /// after --timeout-secs; failures become error rows. A baseline that is not installed
    /// is named as missing in the report, which continues without it.
    ///
    /// Examples: scode report ../shared/corpus -o report/
    ///           scode report --quick a.obj b.obj -o /tmp/r --jobs 2
    ///           scode report ../shared/corpus/step -o rep/ --jobs 2 --resume
    #[command(verbatim_doc_comment)]
    Report(ReportArgs),
    /// Internal: one encode of `scode report` in a child process (argument: job JSON).
    #[command(hide = true, name = "report-step")]
    ReportStep { job: String },
}

/// The output file of a command: positional or `-o`, exactly one of them.
#[derive(Args, Debug, Clone)]
pub struct OutputArg {
    /// Output file (alternatively use -o).
    #[arg(value_name = "OUTPUT")]
    pub output: Option<PathBuf>,
    /// Output file (alternatively give it positionally).
    #[arg(short = 'o', long = "output", value_name = "OUTPUT")]
    pub output_flag: Option<PathBuf>,
}

impl OutputArg {
    pub fn path(&self) -> Result<&Path> {
        match (&self.output, &self.output_flag) {
            (Some(a), Some(b)) if a != b => Err(CliError::Usage(format!(
                "two different outputs given ({} and -o {}); give one",
                a.display(),
                b.display()
            ))
            .into()),
            (Some(a), _) | (None, Some(a)) => Ok(a),
            (None, None) => {
                Err(CliError::Usage("no output file given: add OUTPUT or -o OUTPUT".into()).into())
            }
        }
    }

    /// The output path of a command that reads `input` and writes `writes`: refused when
    /// it is the input (writing would destroy what is being read) or when its extension
    /// names another format than the bytes written (a `.obj` holding `.scode` bytes is read
    /// back as a broken mesh).
    pub fn checked(&self, input: &Path, writes: Writes) -> Result<&Path> {
        let output = self.path()?;
        if same_file(input, output) {
            return Err(CliError::Usage(format!(
                "the output {} is the input file; give another output",
                output.display()
            ))
            .into());
        }
        let ext = output
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match writes {
            Writes::Scode if ext.as_deref() != Some("scode") => Err(CliError::Usage(format!(
                "the output {} must end in .scode: this command writes a .scode file",
                output.display()
            ))
            .into()),
            Writes::Mesh if ext.as_deref() == Some("scode") => Err(CliError::Usage(format!(
                "the output {} ends in .scode, but this command writes a mesh; give a mesh \
                 extension (.obj .ply .stl .glb .gltf .off)",
                output.display()
            ))
            .into()),
            Writes::Mesh => match MeshFormat::from_path(output) {
                Ok(_) => Ok(output),
                Err(e) => Err(CliError::Usage(e.to_string()).into()),
            },
            Writes::Scode => Ok(output),
        }
    }
}

/// What a command writes, which its output's extension must name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Writes {
    /// A `.scode` file.
    Scode,
    /// A mesh file, its format chosen by the extension.
    Mesh,
}

/// Whether `a` and `b` name one existing file, through symbolic links, `..` and (on unix)
/// hard links, which share the device and inode but not the path.
pub fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if ma.dev() == mb.dev() && ma.ino() == mb.ino() {
            return true;
        }
    }
    #[cfg(not(unix))]
    let _ = (ma, mb);
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

#[derive(Args, Debug)]
pub struct EncodeArgs {
    /// Input mesh (.obj .ply .stl .glb .gltf .off) or STEP file (.step .stp).
    pub input: PathBuf,
    #[command(flatten)]
    pub output: OutputArg,
    /// Store the input mesh itself as the control mesh (no fitting).
    #[arg(long)]
    pub raw: bool,
    /// Quantisation bits per coordinate (4..=24). Each extra bit halves the position error.
    /// Default: 10 with --raw; when fitting, the fewest bits that keep the quantisation error
    /// below a quarter of the tolerance.
    #[arg(long, value_name = "BITS")]
    pub bits: Option<u8>,
    /// Largest allowed distance between input and decoded surface, in model units (or as a
    /// fraction of the bounding-box diagonal with --relative). Default: 1e-3 of the diagonal.
    #[arg(long, value_name = "DIST")]
    pub tolerance: Option<f64>,
    /// Largest allowed mean distance between input and decoded surface (same units as
    /// --tolerance). Without it only the max is bounded, and the encoder may coarsen the
    /// quantisation until the mean grows; with it, e.g. `--tolerance 0.008 --mean-tolerance
    /// 0.001 --relative`, both hold (the seed coders' operating point).
    #[arg(long, value_name = "DIST")]
    pub mean_tolerance: Option<f64>,
    /// Read --tolerance and --mean-tolerance as fractions of the bounding-box diagonal.
    #[arg(long)]
    pub relative: bool,
    /// Hold the tolerance beyond the input's own chord error instead of to the input mesh
    /// itself: each facet's estimated distance from the CAD surface it tessellates (from its
    /// vertex normals, and from the surface of cylinder and cone faces) is allowed on top.
    /// Without it the tolerance bounds the plain distance between the decoded surface and the
    /// input mesh, which `scode info --against` and any mesh tool measure. Use it for coarse
    /// tessellations of smooth parts: a smooth surface cannot come nearer to a facet than its
    /// sagitta, so without it such faces are stored as their facets (more bytes). A STEP file is always measured against its B-rep (exact surfaces, and the
    /// tessellation plus its chordal tolerance for the other faces).
    #[arg(long)]
    pub chord_allowance: bool,
    /// How hard to search for a smaller file. `default` fits once, with choices decided
    /// from the model; `fast` also skips the relaxation round and quarter-bit quantisation
    /// steps and keeps the fit's own face order (for converting many files); `max` fits the
    /// alternatives (five tessellations of a STEP file; plane and closed-patch treatments of
    /// small meshes) and keeps the smallest file, several times slower for a few percent.
    /// Every effort meets the same tolerance. Example: `scode encode --effort max part.step
    /// part.scode`.
    #[arg(long, value_name = "EFFORT", default_value = "default", value_parser = parse_effort)]
    pub effort: Effort,
    /// Ignore the `.faces.json` sidecar next to the input.
    #[arg(long)]
    pub no_sidecar: bool,
    /// Do not store group (CAD face) names; groups themselves are always kept.
    #[arg(long)]
    pub no_names: bool,
    /// Encode a STEP file even when some of its faces cannot be read (each is named on
    /// stderr) and leave them out. Without it such a file is not encoded and scode exits
    /// with status 6, so a model with holes is never written unnoticed.
    #[arg(long)]
    pub allow_skipped: bool,
    /// Longest time the whole encode (reading, fitting, writing) may take, in seconds. Over
    /// it scode stops every thread of the encode by exiting, writes nothing, and exits with
    /// status 4. Default: no limit (a STEP file's own reading timeouts still apply).
    #[arg(long, value_name = "SECONDS", value_parser = parse_seconds)]
    pub max_seconds: Option<f64>,
    /// Largest resident memory the whole encode may hold, in bytes (suffixes K, M, G for
    /// KiB, MiB, GiB: `--max-memory 2G`). The process's resident set is read every few
    /// milliseconds; over the budget scode stops every thread of the encode by exiting,
    /// writes nothing, and exits with status 4. A burst of allocation between two readings
    /// can pass the budget by what it allocates in that time. Linux only (it reads
    /// /proc/self/status). Default: no limit.
    #[arg(long, value_name = "BYTES", value_parser = parse_memory)]
    pub max_memory: Option<u64>,
    /// Print what the reader repaired and per-stage timings.
    #[arg(short, long)]
    pub verbose: bool,
}

impl EncodeArgs {
    /// --tolerance as given (read with --relative), else the encoder's default.
    pub fn tolerance(&self) -> Tolerance {
        self.tolerance
            .map_or(Tolerance::DEFAULT, |t| Tolerance::new(t, self.relative))
    }

    /// --mean-tolerance as given (read with --relative).
    pub fn mean_tolerance(&self) -> Option<Tolerance> {
        self.mean_tolerance
            .map(|t| Tolerance::new(t, self.relative))
    }
}

#[derive(Args, Debug)]
pub struct DecodeArgs {
    /// Input .scode file.
    pub input: PathBuf,
    #[command(flatten)]
    pub output: OutputArg,
    /// Largest distance between the output and the file's limit surface, in model units
    /// (with --relative, a fraction of the surface's bounding-box diagonal). Each control
    /// triangle gets the coarsest level whose measured distance from the limit surface
    /// (against the limit points two levels finer, plus the shrinking remainder beyond
    /// them) is within it. Looser than the file's: fewer triangles, e.g. for a preview;
    /// tighter: more (the finest level allowed is one beyond the file's default level, and
    /// one more per factor 4 of a tighter tolerance).
    /// Default: the tolerance the file was encoded for.
    #[arg(long, value_name = "T", conflicts_with = "level")]
    pub tolerance: Option<f64>,
    /// Read --tolerance as a fraction of the bounding-box diagonal.
    #[arg(long, requires = "tolerance")]
    pub relative: bool,
    /// Subdivide every face of a control mesh uniformly to this level instead of decoding to
    /// a tolerance (the file's default level is the surface the encoder measured).
    #[arg(long, value_name = "N")]
    pub level: Option<u32>,
    /// Move output vertices to the limit surface and write normals (always on for fitted
    /// control meshes unless --no-limit).
    #[arg(long)]
    pub limit: bool,
    /// Keep level-N positions instead of limit positions for fitted control meshes (a
    /// uniform level: the file's default level unless --level).
    #[arg(long, conflicts_with_all = ["limit", "tolerance"])]
    pub no_limit: bool,
    /// Longest edge of the output, in model units: every longer edge is split at its midpoint, the same
    /// way for both faces beside it, so the mesh stays watertight and keeps its groups, sharp
    /// edges and corners; edges inside a plane are then flipped toward well-shaped
    /// triangles. For solvers that need an element size, e.g. --max-edge 2.5.
    #[arg(long, value_name = "H")]
    pub max_edge: Option<f64>,
    /// With --max-edge: the smallest angle in degrees (up to 30) of the triangles inside
    /// plane patches, which are triangulated anew by constrained Delaunay refinement inside
    /// their outlines (the outline's edges stay as they are, so the mesh stays watertight);
    /// curved patches keep the triangles --max-edge gives. E.g. --max-edge 2.5 --min-angle 25.
    #[arg(long, value_name = "DEGREES", requires = "max_edge")]
    pub min_angle: Option<f64>,
    /// Output boundary patches (planes, cylinders, cones) as the full 1-to-4 grid instead of
    /// S-CODE's sparse triangulation.
    #[arg(long)]
    pub dense_boundary: bool,
    /// glTF output only: store positions as 16-bit and normals as 8-bit integers
    /// (KHR_mesh_quantization; positions keep about 1.5e-5 of the model's half size),
    /// about half the bytes of float output.
    #[arg(long)]
    pub quantize: bool,
    #[command(flatten)]
    pub limits: DecodeLimits,
}

/// Memory budget of `scode decode` and `scode info`: the library's default. A decode to
/// the file's tolerance (the default) is charged for what its measurement may hold and for
/// the output of the levels it chooses, which is far below a uniform level's: the benchmark
/// models take at most a few hundred MB, a fine tessellation of 100,000 faces fitted at
/// 5e-4 about 1.06 GB of it. A uniform `--level` is charged 200 bytes per triangle (5 M
/// triangles per GiB); larger levels need `--max-memory`.
const DEFAULT_MAX_MEMORY: u64 = 1 << 30;

/// What decoding a `.scode` file may cost (a file that needs more is refused before the
/// memory is allocated).
#[derive(Args, Debug)]
pub struct DecodeLimits {
    /// Refuse files larger than this many bytes (checked before the file is read).
    #[arg(long, value_name = "BYTES", default_value_t = Limits::default().max_input_bytes)]
    pub max_bytes: u64,
    /// Memory budget of the decode in bytes: the input, every array sized by the file's
    /// counts and the subdivided surface are charged against it before they are allocated
    /// (and released when freed), and what is live at once must fit. The default (1 GiB)
    /// fits decodes to the file's tolerance of large CAD models; a uniform --level takes 200
    /// bytes per triangle (840 faces at level 5 need 2.2 GB: --max-memory 3000000000).
    #[arg(long, value_name = "BYTES", default_value_t = DEFAULT_MAX_MEMORY)]
    pub max_memory: u64,
    /// Work bound of the decode: steps of the walks whose length the file decides, per
    /// vertex, face and face corner. Lattices of more than about 30,000 tunnels may need more
    /// than the default.
    #[arg(long, value_name = "N", default_value_t = Limits::default().max_work_per_element)]
    pub max_work_per_element: u64,
}

impl DecodeLimits {
    pub fn limits(&self) -> Limits {
        Limits {
            max_input_bytes: self.max_bytes,
            max_memory: self.max_memory,
            max_work_per_element: self.max_work_per_element,
            ..Limits::default()
        }
    }
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// A .scode file or a mesh file.
    pub file: PathBuf,
    /// List every group (CAD face) instead of a summary.
    #[arg(long)]
    pub groups: bool,
    /// Measure a .scode file against this mesh: max and RMS distance both ways between the
    /// decoded surface (default level) and the mesh, sampled on each side at every vertex,
    /// 100,000 random points by area and points along every edge longer than 2e-3 of the
    /// diagonal (the max finds thin slivers; the mean and RMS are by area).
    #[arg(long, value_name = "MESH")]
    pub against: Option<PathBuf>,
    #[command(flatten)]
    pub limits: DecodeLimits,
}

#[derive(Args, Debug)]
pub struct SegmentArgs {
    /// A mesh without CAD-face groups (.stl .obj .ply .off ...).
    pub input: PathBuf,
    #[command(flatten)]
    pub output: OutputArg,
    /// Edges whose dihedral angle exceeds this many degrees split faces.
    #[arg(long, default_value_t = 30.0, value_name = "DEG")]
    pub sharp_angle: f64,
}

/// `scode report --reference`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReferenceArg {
    Brep,
    Input,
}

#[derive(Args, Debug)]
pub struct ReportArgs {
    /// Model files and/or directories (searched recursively).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output directory for report.md, results.csv, plots/ and files/.
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: PathBuf,
    /// Fitting tolerances as fractions of the bounding-box diagonal, comma separated
    /// (default 4e-3,2e-3,1e-3,5e-4; with --quick 2e-3).
    #[arg(long, value_delimiter = ',', value_name = "T,T,..")]
    pub tolerances: Option<Vec<f64>>,
    /// Fewer points for a fast pass (CI): one tolerance, Draco -qp 8,10,12,14 at -cl 10,
    /// one timing run.
    #[arg(long)]
    pub quick: bool,
    /// Models measured in parallel (each scode encode also uses threads of its own).
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub jobs: usize,
    /// Directory holding draco_encoder and draco_decoder (default: search PATH).
    #[arg(long, value_name = "DIR")]
    pub draco_dir: Option<PathBuf>,
    /// Directory holding gltfpack (default: search PATH; npm package `gltfpack`).
    #[arg(long, value_name = "DIR")]
    pub gltfpack_dir: Option<PathBuf>,
    /// Timing repeats per step; the median is reported (default 3, 1 with --quick).
    #[arg(long, value_name = "N")]
    pub runs: Option<usize>,
    /// Time limit of one encode (seconds); an overrun is an error row.
    #[arg(long, default_value_t = 600, value_name = "SECS")]
    pub timeout_secs: u64,
    /// Time limit of all steps of one model (seconds): the step running at the limit is
    /// stopped and later steps become error rows. Reading a STEP part (its reference and the
    /// baselines' tessellations) may take half of it; finer tessellations than fit in that
    /// half are left out and said so. Steps run from the loosest tolerance to the tightest,
    /// so the limit cuts the slowest points; raise it for the full curve of large models.
    #[arg(long, default_value_t = scode_cli::report::DEFAULT_MODEL_TIMEOUT_SECS, value_name = "SECS")]
    pub model_timeout_secs: u64,
    /// What errors are measured against: `brep` (the exact B-rep surfaces of a STEP file;
    /// the baselines then get the part tessellated at several chordal tolerances) or
    /// `input` (the input mesh; for a STEP file its tessellation at scode's default chordal
    /// tolerance). Default: brep for STEP files, input for mesh files.
    #[arg(long, value_enum, value_name = "REF")]
    pub reference: Option<ReferenceArg>,
    /// Continue a run that was stopped: models already written to OUT/models/ by a run with
    /// the same options are kept, the others are measured. Every finished model is written
    /// there (and its rows appended to OUT/results.csv) as soon as it is done.
    #[arg(long)]
    pub resume: bool,
}

#[derive(Args, Debug)]
pub struct SubdivideArgs {
    /// Control mesh (.obj with `l` sharp edges, .ply, .stl, .glb, .off) or a .scode file.
    pub input: PathBuf,
    #[command(flatten)]
    pub output: OutputArg,
    /// Number of 1-to-4 refinement steps.
    #[arg(long, default_value_t = 2, value_name = "N")]
    pub level: u32,
    /// Move output vertices to the limit surface and write normals.
    #[arg(long)]
    pub limit: bool,
    /// Output boundary patches as the full 1-to-4 grid instead of the sparse triangulation.
    #[arg(long)]
    pub dense_boundary: bool,
}

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// The .scode file to show.
    pub file: PathBuf,
    /// Local port to listen on (0: any free port).
    #[arg(long, default_value_t = 8765, value_name = "N")]
    pub port: u16,
    /// Only print the URL; do not start a browser.
    #[arg(long)]
    pub no_open: bool,
}

/// `--effort`'s values, with the library's message for an unknown one.
/// A positive, finite number of seconds (at most a year).
fn parse_seconds(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v > 0.0 && v <= 365.0 * 86400.0 {
        Ok(v)
    } else {
        Err(format!(
            "must be a positive number of seconds up to a year, got {s}"
        ))
    }
}

/// A byte count with an optional binary suffix: `1048576`, `512M`, `2G`.
fn parse_memory(s: &str) -> std::result::Result<u64, String> {
    let t = s.trim();
    let (digits, shift) = match t.char_indices().last() {
        Some((i, 'K' | 'k')) => (&t[..i], 10),
        Some((i, 'M' | 'm')) => (&t[..i], 20),
        Some((i, 'G' | 'g')) => (&t[..i], 30),
        _ => (t, 0),
    };
    digits
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(1u64 << shift))
        .filter(|&n| n > 0)
        .ok_or_else(|| format!("must be a positive byte count (suffix K, M or G allowed), got {s}"))
}

fn parse_effort(s: &str) -> std::result::Result<Effort, String> {
    s.parse().map_err(|e: scode::Error| e.to_string())
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Encode(a) => match (a.max_seconds, a.max_memory) {
            (None, None) => commands::encode(&a),
            (seconds, memory) => commands::encode_within(a, seconds, memory),
        },
        Command::Decode(a) => commands::decode(&a),
        Command::Info(a) => commands::info(&a),
        Command::Subdivide(a) => commands::subdivide(&a),
        Command::Segment(a) => commands::segment(&a),
        Command::View(a) => view_command(&a),
        Command::Report(a) => commands::report(&a),
        Command::ReportStep { job } => commands::report_step(&job),
    }
}

fn view_command(args: &ViewArgs) -> Result<()> {
    view::check_scode(&args.file)?;
    let server = view::ViewServer::bind(&args.file, args.port)?;
    let url = server.url()?;
    println!("scode view: {} at {url}", args.file.display());
    println!("(serving until Ctrl-C)");
    use std::io::Write;
    std::io::stdout().flush()?;
    if !args.no_open {
        view::open_browser(&url);
    }
    server.serve()
}

//! Argument parsing and command dispatch for the `scode` binary.

mod commands;

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};

/// scode: a subdivision-surface codec for CAD models.
///
/// scode stores a CAD model as a small control mesh (one patch per CAD face, sharp edges on
/// face boundaries, corners at B-rep vertices) in a compact, checksummed `.scode` file, and
/// rebuilds the smooth, sharp-edged surface at any level of detail when decoding.
///
/// Mesh files are read and written by extension: .obj .ply .stl .glb .gltf (read) .off (read).
#[derive(Parser, Debug)]
#[command(name = "scode", version, about, long_about, propagate_version = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Compress a mesh into a .scode file.
    ///
    /// With --raw the input mesh itself is stored as the control mesh (no fitting): a
    /// Draco-class lossy-by-quantisation coder. Faces keep their degree (quads and n-gons are
    /// not triangulated), OBJ groups, `l` sharp edges and corner tags are kept.
    ///
    /// Example: scode encode --raw part.obj part.scode
    #[command(verbatim_doc_comment)]
    Encode(EncodeArgs),
    /// Decompress a .scode file into a mesh (format chosen by the output extension).
    ///
    /// A raw-mode file decodes to the stored mesh. A control-mesh file is subdivided to
    /// --level (default: the level stored in the file).
    ///
    /// Example: scode decode part.scode part.obj
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
            (Some(a), Some(b)) if a != b => {
                bail!(
                    "two different outputs given ({} and -o {}); give one",
                    a.display(),
                    b.display()
                )
            }
            (Some(a), _) | (None, Some(a)) => Ok(a),
            (None, None) => bail!("no output file given: add OUTPUT or -o OUTPUT"),
        }
    }
}

#[derive(Args, Debug)]
pub struct EncodeArgs {
    /// Input mesh (.obj .ply .stl .glb .gltf .off).
    pub input: PathBuf,
    #[command(flatten)]
    pub output: OutputArg,
    /// Store the input mesh itself as the control mesh (no fitting).
    #[arg(long)]
    pub raw: bool,
    /// Quantisation bits per coordinate (4..=24). Each extra bit halves the position error.
    #[arg(long, default_value_t = 10, value_name = "BITS")]
    pub bits: u8,
    /// Do not store group (CAD face) names; groups themselves are always kept.
    #[arg(long)]
    pub no_names: bool,
    /// Print what the reader repaired and per-stage timings.
    #[arg(short, long)]
    pub verbose: bool,
}

#[derive(Args, Debug)]
pub struct DecodeArgs {
    /// Input .scode file.
    pub input: PathBuf,
    #[command(flatten)]
    pub output: OutputArg,
    /// Subdivision level for control-mesh files (default: the file's own default level).
    #[arg(long, value_name = "N")]
    pub level: Option<u32>,
    /// Move output vertices to the limit surface and write normals.
    #[arg(long)]
    pub limit: bool,
    /// Refuse files larger than this many bytes (a decoder safety limit).
    #[arg(long, value_name = "BYTES")]
    pub max_bytes: Option<u64>,
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    /// A .scode file or a mesh file.
    pub file: PathBuf,
    /// List every group (CAD face) instead of a summary.
    #[arg(long)]
    pub groups: bool,
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
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Encode(a) => commands::encode(&a),
        Command::Decode(a) => commands::decode(&a),
        Command::Info(a) => commands::info(&a),
        Command::Subdivide(a) => commands::subdivide(&a),
    }
}

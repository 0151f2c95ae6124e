//! stub
use std::io::{self, Write};
use std::path::Path;
use super::repair::RawMesh;
use crate::error::{Error, Result};
use crate::mesh::ControlMesh;
pub fn parse(_bytes: &[u8], path: &Path) -> Result<RawMesh> { Err(Error::input(path, "todo")) }
pub fn write(_o: &mut dyn Write, _m: &ControlMesh, _n: Option<&[glam::DVec3]>) -> io::Result<()> { Ok(()) }

//! From a parsed file to a valid [`ControlMesh`]: welding, degenerate-face repair, empty-group
//! and unreferenced-vertex removal, plus the counts that go into the [`ReadReport`].
//!
//! Every format parser produces a [`RawMesh`] and hands it to [`finish`], so all formats get
//! the same repairs, described once in the [module docs of `io`](super).

use glam::DVec3;

use super::weld::{weld_where, Welded};
use super::{MeshFormat, ReadReport};
use crate::error::{Error, Result};
use crate::mesh::{edge_key, ControlMesh, PatchKind};
use std::path::Path;

/// What a format parser hands over: the file's own vertex numbering (0-based and range-checked
/// by the parser, so errors can name a line), before welding and repair. Kept apart from
/// [`ControlMesh`] because a raw file may break every `ControlMesh` invariant (duplicate
/// vertices, repeated indices in a face, empty groups).
#[derive(Clone, Debug, Default)]
pub struct RawMesh {
    pub positions: Vec<DVec3>,
    /// CSR like [`ControlMesh::face_offsets`]; starts with 0.
    pub face_offsets: Vec<u32>,
    pub face_vertices: Vec<u32>,
    pub face_groups: Vec<u32>,
    /// Group names; a face's group indexes this.
    pub group_names: Vec<String>,
    /// Source line of each face (text formats) for messages; empty when not known.
    pub face_lines: Vec<u32>,
    /// Source line of each vertex (text formats) for messages; empty when not known.
    pub vertex_lines: Vec<u32>,
    /// Sharp edges as vertex pairs in file numbering.
    pub sharp_edges: Vec<[u32; 2]>,
    pub corners: Vec<u32>,
    /// Face records in the file, including those the parser already dropped.
    pub input_faces: usize,
    /// Faces the parser dropped because the file gave them fewer than 3 vertices (see
    /// [`RawMesh::drop_short_face`]).
    pub dropped_short_faces: usize,
    /// Where the first few of those were, for the report note.
    pub short_face_examples: Vec<String>,
    /// Parser notes (ignored content, conventions applied); copied into the report.
    pub notes: Vec<String>,
}

impl RawMesh {
    pub fn new() -> Self {
        RawMesh {
            face_offsets: vec![0],
            ..Default::default()
        }
    }

    /// Appends a face (indices already 0-based and in range).
    pub fn push_face(&mut self, vertices: &[u32], group: u32) {
        self.face_vertices.extend_from_slice(vertices);
        self.face_offsets.push(self.face_vertices.len() as u32);
        self.face_groups.push(group);
    }

    pub fn face_count(&self) -> usize {
        self.face_groups.len()
    }

    /// Records a face record with fewer than 3 vertices, which the parser skips. `location`
    /// says where it is (`"line 12"`, `"face 7"`).
    pub fn drop_short_face(&mut self, location: String) {
        self.input_faces += 1;
        self.dropped_short_faces += 1;
        if self.short_face_examples.len() < Examples::MAX_SHOWN {
            self.short_face_examples.push(location);
        }
    }

    fn face(&self, f: usize) -> &[u32] {
        &self.face_vertices[self.face_offsets[f] as usize..self.face_offsets[f + 1] as usize]
    }

    /// "vertex 3 (line 5)" or "vertex 3": how messages name a vertex of the file.
    fn describe_vertex(&self, v: usize) -> String {
        match self.vertex_lines.get(v) {
            Some(line) => format!("vertex {v} (line {line})"),
            None => format!("vertex {v}"),
        }
    }

    /// "face 12 (line 40)" or "face 12": how messages name a face of the file.
    fn describe_face(&self, f: usize) -> String {
        match self.face_lines.get(f) {
            Some(line) => format!("face {f} (line {line})"),
            None => format!("face {f}"),
        }
    }
}

/// Keeps the first few examples of a repair for its note.
struct Examples {
    count: usize,
    shown: Vec<String>,
}

impl Examples {
    const MAX_SHOWN: usize = 5;

    fn new() -> Self {
        Examples {
            count: 0,
            shown: Vec::new(),
        }
    }

    fn add(&mut self, what: impl FnOnce() -> String) {
        self.count += 1;
        if self.shown.len() < Self::MAX_SHOWN {
            self.shown.push(what());
        }
    }

    /// "`count` `text`: a, b, c, ..." or nothing when empty.
    fn note(&self, text: &str, notes: &mut Vec<String>) {
        if self.count == 0 {
            return;
        }
        let more = if self.count > self.shown.len() {
            ", ..."
        } else {
            ""
        };
        notes.push(format!(
            "{} {text}: {}{more}",
            self.count,
            self.shown.join(", ")
        ));
    }
}

/// An error when the positions' bounding box has no finite diagonal, naming the vertices at
/// the ends of its longest side. The encoder measures every distance, tolerance and
/// quantisation step from coordinate differences squared: finite coordinates near 1e154 or
/// beyond make them infinite, and the encoded file would hold a grid the decoder refuses.
fn check_extent(raw: &RawMesh, path: &Path) -> Result<()> {
    let Some((lo, hi)) = crate::mesh::overflowing_extent(&raw.positions) else {
        return Ok(());
    };
    Err(Error::input(
        path,
        format!(
            "coordinates too large: {} at {:?} and {} at {:?} span a bounding box whose \
             diagonal overflows f64 (scale the model down)",
            raw.describe_vertex(lo),
            raw.positions[lo].to_array(),
            raw.describe_vertex(hi),
            raw.positions[hi].to_array()
        ),
    ))
}

/// Welds, repairs and validates a parsed file; see the [`io`](super) module docs for the
/// rules. Errors name `path`.
pub fn finish(raw: RawMesh, format: MeshFormat, path: &Path) -> Result<(ControlMesh, ReadReport)> {
    let mut repair = Repair::start(&raw, format, path);
    check_raw_mesh(&raw, path)?;

    // 1. Weld duplicates that lie on an open boundary of the stored mesh (or are used by no
    //    face): that is where exporters cut surfaces apart. See `weld` for why coincident
    //    vertices inside closed surfaces are not merged.
    let eligible = weld_eligible(&raw);
    let welded = weld_where(&raw.positions, |i| eligible[i]);
    repair.record_weld(&welded);

    // 2. Faces: map to welded vertices, remove repeats, drop those left with < 3.
    let mut faces = repair.repair_faces(&raw, &welded.remap)?;

    // 3. Groups: drop the empty ones, keep the order of the rest.
    let mut mesh = ControlMesh::new();
    repair.drop_empty_groups(&raw, &mut faces.groups, &mut mesh)?;

    // 4. Remove unreferenced vertices, keeping the order of the others.
    let (positions, compact) = repair.remove_unreferenced(&welded.positions, &mut faces.vertices);
    // Maps a file vertex to the final index, if it survived.
    let final_index = |v: u32| -> Option<u32> {
        let c = compact[welded.remap[v as usize] as usize];
        (c != u32::MAX).then_some(c)
    };

    mesh.positions = positions;
    mesh.face_offsets = faces.offsets;
    mesh.face_vertices = faces.vertices;
    mesh.face_groups = faces.groups;

    // 5. Edge statistics (and the edge set for checking sharp edges).
    let edges = sorted_edges(&mesh);
    repair.record_edge_statistics(&mesh, &edges);

    // 6. Sharp edges and corners.
    repair.add_sharp_edges(&raw, &mut mesh, &edges, &final_index)?;
    repair.add_corners(&raw, &mut mesh, &final_index)?;
    let mut report = repair.report;
    report.repairs = repair.notes;

    mesh.validate()
        .map_err(|e| Error::input(path, format!("internal reader error: {e}")))?;
    Ok((mesh, report))
}

/// The safety net every format gets before any repair: some faces, counts that fit u32,
/// finite coordinates with a finite extent, vertex references in range. Parsers check
/// most of these with line numbers.
fn check_raw_mesh(raw: &RawMesh, path: &Path) -> Result<()> {
    if raw.face_count() == 0 {
        let why = if raw.input_faces > 0 {
            "no valid faces (all faces were degenerate)"
        } else if raw.positions.is_empty() {
            "no vertices and no faces (empty or not a mesh file)"
        } else {
            "no faces (a point cloud or polyline file cannot be encoded)"
        };
        return Err(Error::input(path, why));
    }
    if u32::try_from(raw.positions.len()).is_err()
        || u32::try_from(raw.face_vertices.len()).is_err()
    {
        return Err(Error::input(
            path,
            "mesh too large (more than 2^32 vertices or indices)",
        ));
    }
    // Parsers check these with line numbers; this is the safety net for every format.
    if let Some(i) = raw.positions.iter().position(|p| !p.is_finite()) {
        return Err(Error::input(
            path,
            format!(
                "{} has a non-finite coordinate {:?}",
                raw.describe_vertex(i),
                raw.positions[i]
            ),
        ));
    }
    check_extent(raw, path)?;
    let nv = raw.positions.len() as u32;
    for f in 0..raw.face_count() {
        if let Some(&v) = raw.face(f).iter().find(|&&v| v >= nv) {
            return Err(Error::input(
                path,
                format!(
                    "{} references vertex {} but there are only {nv} vertices",
                    raw.describe_face(f),
                    v as u64 + 1
                ),
            ));
        }
    }
    Ok(())
}

/// Faces after repair, as CSR like [`ControlMesh`]'s.
struct RepairedFaces {
    offsets: Vec<u32>,
    vertices: Vec<u32>,
    groups: Vec<u32>,
}

/// The repairs of one file as [`finish`] makes them: the report and its notes so far, and
/// the path errors name.
struct Repair<'p> {
    report: ReadReport,
    notes: Vec<String>,
    path: &'p Path,
}

impl<'p> Repair<'p> {
    /// The report of what the parser saw and dropped, with the parser's notes.
    fn start(raw: &RawMesh, format: MeshFormat, path: &'p Path) -> Self {
        let mut report = ReadReport::new(format);
        report.input_vertices = raw.positions.len();
        report.input_faces = raw.input_faces.max(raw.face_count());
        report.dropped_degenerate_faces = raw.dropped_short_faces;
        let mut notes = raw.notes.clone();
        if raw.dropped_short_faces > 0 {
            Examples {
                count: raw.dropped_short_faces,
                shown: raw.short_face_examples.clone(),
            }
            .note(
                "faces with fewer than 3 vertices in the file dropped",
                &mut notes,
            );
        }
        Repair {
            report,
            notes,
            path,
        }
    }

    /// Reports the welded vertices and the coincident ones left apart.
    fn record_weld(&mut self, welded: &Welded) {
        self.report.welded_vertices = welded.merged();
        self.report.coincident_vertices_kept = welded.coincident_kept;
        if welded.coincident_kept > 0 {
            self.notes.push(format!(
                "{} vertices share coordinates with another vertex but were not welded (inside \
                 closed surfaces, e.g. touching solids; welding would make non-manifold edges)",
                welded.coincident_kept
            ));
        }
    }

    /// The faces on the welded vertices (`remap`: the welded vertex of each file vertex)
    /// with repeated vertices removed (first occurrence kept); those left with fewer than 3
    /// are dropped. Fails when none is left.
    fn repair_faces(&mut self, raw: &RawMesh, remap: &[u32]) -> Result<RepairedFaces> {
        let mut face_offsets = Vec::with_capacity(raw.face_count() + 1);
        face_offsets.push(0u32);
        let mut face_vertices = Vec::with_capacity(raw.face_vertices.len());
        let mut face_groups = Vec::with_capacity(raw.face_count());
        let mut dropped = Examples::new();
        let mut repaired = Examples::new();
        let mut polygon = Vec::new();
        for f in 0..raw.face_count() {
            polygon.clear();
            for &v in raw.face(f) {
                let w = remap[v as usize];
                if !polygon.contains(&w) {
                    polygon.push(w);
                }
            }
            if polygon.len() < 3 {
                dropped.add(|| raw.describe_face(f));
                continue;
            }
            if polygon.len() != raw.face(f).len() {
                repaired.add(|| raw.describe_face(f));
            }
            face_vertices.extend_from_slice(&polygon);
            face_offsets.push(face_vertices.len() as u32);
            face_groups.push(raw.face_groups[f]);
        }
        self.report.dropped_degenerate_faces += dropped.count;
        self.report.repaired_faces = repaired.count;
        dropped.note(
            "degenerate faces dropped (fewer than 3 distinct vertices after welding)",
            &mut self.notes,
        );
        repaired.note(
            "faces repaired by removing repeated vertices (first occurrence kept)",
            &mut self.notes,
        );
        if face_groups.is_empty() {
            return Err(Error::input(
                self.path,
                format!(
                    "no valid faces: all {} faces are degenerate (fewer than 3 distinct vertices)",
                    raw.face_count()
                ),
            ));
        }
        Ok(RepairedFaces {
            offsets: face_offsets,
            vertices: face_vertices,
            groups: face_groups,
        })
    }

    /// Adds the groups that have faces to `mesh`, in file order, and renumbers `face_groups`
    /// to them; the empty ones are dropped.
    fn drop_empty_groups(
        &mut self,
        raw: &RawMesh,
        face_groups: &mut [u32],
        mesh: &mut ControlMesh,
    ) -> Result<()> {
        let mut faces_per_group = vec![0usize; raw.group_names.len()];
        for &g in face_groups.iter() {
            match faces_per_group.get_mut(g as usize) {
                Some(n) => *n += 1,
                None => {
                    return Err(Error::input(
                        self.path,
                        format!("internal reader error: face group {g} does not exist"),
                    ))
                }
            }
        }
        let mut group_remap = vec![u32::MAX; raw.group_names.len()];
        let mut empty = Examples::new();
        for (g, name) in raw.group_names.iter().enumerate() {
            if faces_per_group[g] == 0 {
                empty.add(|| format!("`{name}`"));
            } else {
                group_remap[g] = mesh.push_group(name.clone(), PatchKind::default());
            }
        }
        self.report.dropped_empty_groups = empty.count;
        empty.note("empty groups dropped (no faces)", &mut self.notes);
        for g in face_groups.iter_mut() {
            *g = group_remap[*g as usize];
        }
        Ok(())
    }

    /// Removes the welded vertices no face uses, keeping the order of the others, and
    /// renumbers `face_vertices`. Returns the kept positions and the new index of every
    /// welded vertex (`u32::MAX` for those removed).
    fn remove_unreferenced(
        &mut self,
        welded_positions: &[DVec3],
        face_vertices: &mut [u32],
    ) -> (Vec<DVec3>, Vec<u32>) {
        let mut compact = vec![u32::MAX; welded_positions.len()];
        for &v in face_vertices.iter() {
            compact[v as usize] = 0;
        }
        let mut positions = Vec::with_capacity(welded_positions.len());
        for (v, slot) in compact.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = positions.len() as u32;
                positions.push(welded_positions[v]);
            }
        }
        self.report.unreferenced_vertices = welded_positions.len() - positions.len();
        if self.report.unreferenced_vertices > 0 {
            self.notes.push(format!(
                "{} vertices used by no face removed",
                self.report.unreferenced_vertices
            ));
        }
        for v in face_vertices.iter_mut() {
            *v = compact[*v as usize];
        }
        (positions, compact)
    }

    /// Reports the boundary and non-manifold edges (from `edges`, the mesh's sorted edges)
    /// and the zero-area faces.
    fn record_edge_statistics(&mut self, mesh: &ControlMesh, edges: &[(u32, u32)]) {
        let (boundary, nonmanifold) = count_edge_multiplicities(edges);
        self.report.boundary_edges = boundary;
        self.report.nonmanifold_edges = nonmanifold;
        self.report.zero_area_faces = (0..mesh.face_count())
            .filter(|&f| is_zero_area(&mesh.positions, mesh.face(f)))
            .count();
    }

    /// Marks the file's sharp edges on `mesh` (`final_index`: the mesh vertex of a file
    /// vertex that survived); those that are no edge of it (in sorted `edges`) are dropped.
    /// Fails on a sharp edge naming a vertex beyond the file's.
    fn add_sharp_edges(
        &mut self,
        raw: &RawMesh,
        mesh: &mut ControlMesh,
        edges: &[(u32, u32)],
        final_index: &impl Fn(u32) -> Option<u32>,
    ) -> Result<()> {
        let nv = raw.positions.len() as u32;
        let mut bad_sharp = Examples::new();
        for &[a, b] in &raw.sharp_edges {
            if a >= nv || b >= nv {
                return Err(Error::input(
                    self.path,
                    format!(
                        "sharp edge ({}, {}) references a vertex beyond the {nv} vertices",
                        a as u64 + 1,
                        b as u64 + 1
                    ),
                ));
            }
            match (final_index(a), final_index(b)) {
                (Some(x), Some(y)) if x != y && edges.binary_search(&edge_key(x, y)).is_ok() => {
                    mesh.set_sharp(x, y);
                }
                _ => bad_sharp.add(|| format!("({}, {})", a as u64 + 1, b as u64 + 1)),
            }
        }
        self.report.dropped_sharp_edges = bad_sharp.count;
        bad_sharp.note(
            "sharp edges dropped (not an edge of any face after welding; 1-based file vertices)",
            &mut self.notes,
        );
        Ok(())
    }

    /// Tags the file's corners on `mesh` (`final_index` as in
    /// [`add_sharp_edges`](Self::add_sharp_edges)); those whose vertex no face uses are
    /// dropped. Fails on a corner beyond the file's vertices.
    fn add_corners(
        &mut self,
        raw: &RawMesh,
        mesh: &mut ControlMesh,
        final_index: &impl Fn(u32) -> Option<u32>,
    ) -> Result<()> {
        let nv = raw.positions.len() as u32;
        let mut bad_corner = Examples::new();
        for &c in &raw.corners {
            if c >= nv {
                return Err(Error::input(
                    self.path,
                    format!(
                        "corner vertex {} does not exist ({nv} vertices)",
                        c as u64 + 1
                    ),
                ));
            }
            match final_index(c) {
                Some(x) => {
                    mesh.corners.insert(x);
                }
                None => bad_corner.add(|| format!("{}", c as u64 + 1)),
            }
        }
        self.report.dropped_corners = bad_corner.count;
        bad_corner.note(
            "corners dropped (vertex used by no face; 1-based file vertices)",
            &mut self.notes,
        );
        Ok(())
    }
}

/// Vertices that may be welded: those on an edge used by exactly one face of the stored mesh,
/// and those no face uses.
fn weld_eligible(raw: &RawMesh) -> Vec<bool> {
    let mut used = vec![false; raw.positions.len()];
    for &v in &raw.face_vertices {
        used[v as usize] = true;
    }
    let edges = sort_edges(&raw.face_offsets, &raw.face_vertices, raw.positions.len());
    let mut eligible: Vec<bool> = used.iter().map(|&u| !u).collect();
    for_each_edge_run(&edges, |(a, b), n| {
        if n == 1 {
            eligible[a as usize] = true;
            eligible[b as usize] = true;
        }
    });
    eligible
}

/// All face edges as normalised `(min, max)` keys, sorted, one entry per face side (so an
/// edge shared by two faces appears twice). Self-edges (repeated vertex) are skipped.
pub fn sorted_edges(mesh: &ControlMesh) -> Vec<(u32, u32)> {
    sort_edges(&mesh.face_offsets, &mesh.face_vertices, mesh.vertex_count())
}

/// Counting sort by the smaller vertex, then a tiny sort per vertex: linear time, which
/// matters for 100k-face inputs (a comparison sort of all edges dominated reading time).
fn sort_edges(face_offsets: &[u32], face_vertices: &[u32], vertex_count: usize) -> Vec<(u32, u32)> {
    let for_each_side = |f: &mut dyn FnMut(u32, u32)| {
        for w in face_offsets.windows(2) {
            let face = &face_vertices[w[0] as usize..w[1] as usize];
            let mut prev = match face.last() {
                Some(&v) => v,
                None => continue,
            };
            for &v in face {
                if v != prev {
                    let (a, b) = edge_key(prev, v);
                    f(a, b);
                }
                prev = v;
            }
        }
    };
    let mut start = vec![0u32; vertex_count + 1];
    for_each_side(&mut |a, _| start[a as usize + 1] += 1);
    for v in 0..vertex_count {
        start[v + 1] += start[v];
    }
    let total = start[vertex_count] as usize;
    let mut next = start.clone();
    let mut edges = vec![(0u32, 0u32); total];
    for_each_side(&mut |a, b| {
        let slot = &mut next[a as usize];
        edges[*slot as usize] = (a, b);
        *slot += 1;
    });
    for v in 0..vertex_count {
        edges[start[v] as usize..start[v + 1] as usize].sort_unstable();
    }
    edges
}

/// Calls `f(edge, multiplicity)` for each distinct edge of a sorted edge list.
fn for_each_edge_run(sorted: &[(u32, u32)], mut f: impl FnMut((u32, u32), usize)) {
    let mut i = 0;
    while i < sorted.len() {
        let mut j = i + 1;
        while j < sorted.len() && sorted[j] == sorted[i] {
            j += 1;
        }
        f(sorted[i], j - i);
        i = j;
    }
}

/// `(boundary, nonmanifold)`: edges used by exactly one face, and by more than two faces,
/// counted from the output of [`sorted_edges`].
pub fn count_edge_multiplicities(sorted: &[(u32, u32)]) -> (usize, usize) {
    let (mut boundary, mut nonmanifold) = (0, 0);
    for_each_edge_run(sorted, |_, n| match n {
        1 => boundary += 1,
        2 => {}
        _ => nonmanifold += 1,
    });
    (boundary, nonmanifold)
}

/// True when the polygon's (Newell) area is below `1e-12 × (longest edge)²`, i.e. its
/// vertices are collinear up to rounding.
pub fn is_zero_area(positions: &[DVec3], face: &[u32]) -> bool {
    let mut twice_area = DVec3::ZERO;
    let mut longest_sq: f64 = 0.0;
    let origin = positions[face[0] as usize];
    for (i, &a) in face.iter().enumerate() {
        let pa = positions[a as usize] - origin;
        let pb = positions[face[(i + 1) % face.len()] as usize] - origin;
        twice_area += pa.cross(pb);
        longest_sq = longest_sq.max((pb - pa).length_squared());
    }
    0.5 * twice_area.length() <= 1e-12 * longest_sq
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_raw() -> RawMesh {
        let mut raw = RawMesh::new();
        for p in [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
            raw.positions.push(DVec3::from(p));
        }
        raw.group_names.push("a".into());
        raw.push_face(&[0, 1, 2], 0);
        raw.push_face(&[0, 2, 3], 0);
        raw.input_faces = 2;
        raw
    }

    /// Finite coordinates whose box has no finite diagonal are refused at read time with
    /// the file, the vertices and their lines named; large boxes that still have one are
    /// read.
    #[test]
    fn coordinates_whose_box_overflows_are_refused() {
        let obj = "v 0 0 0\nv 1.7e308 0 0\nv -1.7e308 1 0\nf 1 2 3\n";
        let e = crate::io::read_mesh_bytes(obj.as_bytes(), MeshFormat::Obj, Path::new("big.obj"))
            .unwrap_err();
        assert!(matches!(e, Error::Input { .. }), "{e}");
        let msg = e.to_string();
        assert!(msg.starts_with("big.obj: coordinates too large"), "{msg}");
        assert!(
            msg.contains("vertex 2 (line 3)") && msg.contains("vertex 1 (line 2)"),
            "{msg}"
        );
        // The diagonal squares the sides: 1e155 overflows already, 1e150 does not.
        for (side, ok) in [(1e155, false), (1e150, true)] {
            let mut raw = square_raw();
            raw.positions[2] = DVec3::new(side, side, 0.0);
            assert_eq!(
                finish(raw, MeshFormat::Stl, Path::new("t.stl")).is_ok(),
                ok,
                "{side}"
            );
        }
        let mut raw = square_raw();
        raw.positions[1].x = 1e300;
        let msg = finish(raw, MeshFormat::Ply, Path::new("t.ply"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("vertex 0 at") && msg.contains("vertex 1 at"),
            "{msg}"
        );
    }

    #[test]
    fn clean_input_is_unchanged() {
        let (mesh, report) = finish(square_raw(), MeshFormat::Obj, Path::new("t.obj")).unwrap();
        assert_eq!(mesh.vertex_count(), 4);
        assert_eq!(mesh.face_count(), 2);
        assert!(report.unchanged(), "{report}");
        assert_eq!(report.boundary_edges, 4);
        assert_eq!(report.nonmanifold_edges, 0);
    }

    #[test]
    fn repairs_are_counted_and_noted() {
        let mut raw = square_raw();
        // Duplicate of vertex 2, used by a face that becomes degenerate, and one that is
        // repaired by dropping the repeat.
        raw.positions.push(DVec3::new(1.0, 1.0, 0.0)); // 4 == 2
        raw.positions.push(DVec3::new(5.0, 5.0, 5.0)); // 5: unreferenced
        raw.push_face(&[2, 4, 0], 0); // degenerate after welding
        raw.group_names.push("empty".into());
        raw.group_names.push("b".into());
        raw.push_face(&[1, 2, 4, 3], 2); // repaired to 1 2 3
        raw.sharp_edges.push([0, 4]); // becomes (0, 2): a diagonal, a mesh edge
        raw.sharp_edges.push([2, 4]); // collapses
        raw.corners.push(5); // unreferenced
        raw.corners.push(4);
        raw.input_faces = 4;
        let (mesh, report) = finish(raw, MeshFormat::Obj, Path::new("t.obj")).unwrap();
        assert_eq!(report.welded_vertices, 1);
        assert_eq!(report.unreferenced_vertices, 1);
        assert_eq!(report.dropped_degenerate_faces, 1);
        assert_eq!(report.repaired_faces, 1);
        assert_eq!(report.dropped_empty_groups, 1);
        assert_eq!(mesh.face_count(), 3);
        assert_eq!(mesh.face(2), &[1, 2, 3]);
        assert_eq!(mesh.groups.len(), 2);
        assert_eq!(mesh.groups[1].name, "b");
        assert_eq!(mesh.face_groups, vec![0, 0, 1]);
        assert!(mesh.is_sharp(0, 2));
        assert_eq!(mesh.sharp_edges.len(), 1);
        assert_eq!(mesh.corners.iter().copied().collect::<Vec<_>>(), vec![2]);
        assert_eq!(report.nonmanifold_edges, 0);
        let text = report.repairs.join("\n");
        for needle in [
            "degenerate",
            "repeated",
            "empty groups",
            "`empty`",
            "sharp",
            "corner",
        ] {
            assert!(text.contains(needle), "missing `{needle}` in {text}");
        }
        assert!(!report.unchanged());
    }

    #[test]
    fn counts_nonmanifold_and_zero_area() {
        let mut raw = square_raw();
        raw.positions.push(DVec3::new(0.5, 0.5, 1.0));
        raw.positions.push(DVec3::new(2.0, 2.0, 0.0)); // collinear with 0 and 2
        raw.push_face(&[0, 2, 4], 0); // third face on edge 0-2
        raw.push_face(&[0, 2, 5], 0); // fourth face, zero area
        let (_, report) = finish(raw, MeshFormat::Obj, Path::new("t.obj")).unwrap();
        assert_eq!(report.nonmanifold_edges, 1);
        assert_eq!(report.zero_area_faces, 1);
    }

    #[test]
    fn no_faces_or_all_degenerate_is_an_error() {
        let mut raw = RawMesh::new();
        raw.positions.push(DVec3::ZERO);
        let err = finish(raw, MeshFormat::Obj, Path::new("p.obj")).unwrap_err();
        assert!(err.to_string().contains("p.obj") && err.to_string().contains("no faces"));

        let mut raw = square_raw();
        raw.positions[1] = raw.positions[0];
        raw.positions[2] = raw.positions[0];
        raw.positions[3] = raw.positions[0];
        let err = finish(raw, MeshFormat::Obj, Path::new("p.obj")).unwrap_err();
        assert!(err.to_string().contains("degenerate"), "{err}");
    }
}

#[cfg(test)]
mod proptests {
    use super::*;
    use proptest::prelude::*;

    /// Random small polygon soups: (vertex count, faces as index lists).
    fn soup() -> impl Strategy<Value = (usize, Vec<Vec<u32>>)> {
        (3usize..12).prop_flat_map(|nv| {
            let face = prop::collection::vec(0..nv as u32, 3..6);
            (Just(nv), prop::collection::vec(face, 1..20))
        })
    }

    proptest! {
        #[test]
        fn sort_edges_matches_comparison_sort((nv, faces) in soup()) {
            let mut offsets = vec![0u32];
            let mut verts = Vec::new();
            for f in &faces {
                verts.extend_from_slice(f);
                offsets.push(verts.len() as u32);
            }
            let mut expected = Vec::new();
            for f in &faces {
                for i in 0..f.len() {
                    let (a, b) = (f[i], f[(i + 1) % f.len()]);
                    if a != b {
                        expected.push(edge_key(a, b));
                    }
                }
            }
            expected.sort();
            prop_assert_eq!(sort_edges(&offsets, &verts, nv), expected);
        }

        /// Whatever the soup, `finish` returns a valid mesh or an error, never panics, and
        /// its counts add up.
        #[test]
        fn finish_always_yields_valid_meshes((nv, faces) in soup(), dup in 0usize..3) {
            let mut raw = RawMesh::new();
            for i in 0..nv {
                // Some duplicate positions so welding has work to do.
                let k = if dup > 0 { i % (nv - dup) } else { i };
                raw.positions.push(DVec3::new(k as f64, (k * k) as f64, -(k as f64)));
            }
            raw.group_names = vec!["a".into(), "b".into(), "c".into()];
            for (i, f) in faces.iter().enumerate() {
                raw.push_face(f, (i % 2) as u32);
            }
            raw.input_faces = faces.len();
            match finish(raw, MeshFormat::Obj, Path::new("p.obj")) {
                Ok((mesh, report)) => {
                    mesh.validate().unwrap();
                    prop_assert_eq!(
                        mesh.face_count() + report.dropped_degenerate_faces,
                        faces.len()
                    );
                    prop_assert_eq!(
                        mesh.vertex_count() + report.welded_vertices + report.unreferenced_vertices,
                        nv
                    );
                    prop_assert!(report.dropped_empty_groups >= 1); // group "c"
                }
                Err(e) => prop_assert!(e.to_string().contains("degenerate"), "{}", e),
            }
        }
    }
}

//! WebAssembly bindings of the scode decoder and LOD subdivision engine, for the viewer page
//! in `../viewer`. Built by `viewer/build.sh` (wasm32-unknown-unknown + wasm-bindgen).
//!
//! JavaScript usage:
//! ```js
//! const model = new ScodeModel(bytes);          // decode -> control mesh handle
//! model.refine(model.levelForBudget(2e6));      // topology + positions of the finest level, once
//! let mesh = model.extractUniform(3);           // or: model.extractLevels(levelsPerBaseTriangle)
//! const levels = model.viewLevels(mvp, w, h, 8); // S-CODE §4 level per base triangle
//! mesh = model.extractLevels(levels);
//! gl.bufferData(..., mesh.takePositions());     // Float32Array; takeNormals, takeIndices
//!                                               // (Uint32Array), takeGroups (per vertex), takeLines
//! ```
#![forbid(unsafe_code)]

pub mod engine;

use wasm_bindgen::prelude::*;

use engine::{MeshArrays, Model};

fn js_err(e: scode::Error) -> JsError {
    JsError::new(&e.to_string())
}

/// A decoded `.scode` file (control mesh handle) and, after `refine`, its refinement.
#[wasm_bindgen]
pub struct ScodeModel {
    model: Model,
}

#[wasm_bindgen]
impl ScodeModel {
    /// Decodes the bytes of a `.scode` file.
    #[wasm_bindgen(constructor)]
    pub fn new(bytes: &[u8]) -> Result<ScodeModel, JsError> {
        Ok(ScodeModel {
            model: Model::decode(bytes).map_err(js_err)?,
        })
    }

    #[wasm_bindgen(getter, js_name = vertexCount)]
    pub fn vertex_count(&self) -> u32 {
        self.model.mesh.vertex_count() as u32
    }

    #[wasm_bindgen(getter, js_name = faceCount)]
    pub fn face_count(&self) -> u32 {
        self.model.mesh.face_count() as u32
    }

    #[wasm_bindgen(getter, js_name = baseTriangleCount)]
    pub fn base_triangle_count(&self) -> u32 {
        self.model.base_triangle_count() as u32
    }

    #[wasm_bindgen(getter, js_name = groupCount)]
    pub fn group_count(&self) -> u32 {
        self.model.mesh.groups.len() as u32
    }

    /// Name of group (CAD face) `g` (empty when the file stores none).
    #[wasm_bindgen(js_name = groupName)]
    pub fn group_name(&self, g: u32) -> String {
        self.model
            .mesh
            .groups
            .get(g as usize)
            .map(|gr| gr.name.clone())
            .unwrap_or_default()
    }

    /// True for a control mesh (subdivided when shown), false for a raw-mode mesh.
    #[wasm_bindgen(getter, js_name = isControlMesh)]
    pub fn is_control_mesh(&self) -> bool {
        self.model.is_control_mesh()
    }

    /// The level the encoder suggests for display (0 for raw meshes).
    #[wasm_bindgen(getter, js_name = defaultLevel)]
    pub fn default_level(&self) -> u32 {
        match self.model.header.content {
            scode::codec::Content::ControlMesh { default_level } => default_level as u32,
            scode::codec::Content::RawMesh => 0,
        }
    }

    /// The highest level whose uniform refinement stays within `max_triangles`.
    #[wasm_bindgen(js_name = levelForBudget)]
    pub fn level_for_budget(&self, max_triangles: f64) -> u32 {
        self.model.level_for_budget(max_triangles)
    }

    /// Builds the refinement to `max_level` (topology, finest positions, normals).
    pub fn refine(&mut self, max_level: u32) -> Result<(), JsError> {
        self.model.refine(max_level).map_err(js_err)
    }

    /// Level built by `refine` (-1 before).
    #[wasm_bindgen(getter, js_name = maxLevel)]
    pub fn max_level(&self) -> i32 {
        self.model.max_level().map_or(-1, |l| l as i32)
    }

    /// `[minx, miny, minz, maxx, maxy, maxz]` of the surface.
    pub fn bounds(&self) -> Vec<f64> {
        let [lo, hi] = self.model.bounds();
        vec![lo.x, lo.y, lo.z, hi.x, hi.y, hi.z]
    }

    /// The whole surface at one level.
    #[wasm_bindgen(js_name = extractUniform)]
    pub fn extract_uniform(&self, level: u32) -> Result<MeshData, JsError> {
        self.model
            .extract_uniform(level)
            .map(MeshData::from)
            .map_err(js_err)
    }

    /// The surface with base triangle k at `levels[k]`, crack-free.
    #[wasm_bindgen(js_name = extractLevels)]
    pub fn extract_levels(&mut self, levels: &[u8]) -> Result<MeshData, JsError> {
        self.model
            .extract_levels(levels)
            .map(MeshData::from)
            .map_err(js_err)
    }

    /// Level per base triangle from its projected size (column-major `mvp`, viewport in
    /// pixels, longest projected edge after refinement at most `target_px`).
    #[wasm_bindgen(js_name = viewLevels)]
    pub fn view_levels(
        &self,
        mvp: &[f32],
        width: f32,
        height: f32,
        target_px: f32,
    ) -> Result<Vec<u8>, JsError> {
        let m: [f32; 16] = mvp
            .try_into()
            .map_err(|_| JsError::new("viewLevels: mvp must have 16 numbers"))?;
        self.model
            .view_levels(&m, width, height, target_px)
            .map_err(js_err)
    }
}

/// Typed arrays of one extracted mesh. Each `take*` method moves its array into a new JS typed
/// array (no second copy) and leaves it empty, so read each once; the counts stay valid.
#[wasm_bindgen]
pub struct MeshData {
    arrays: MeshArrays,
    triangles: u32,
    vertices: u32,
}

impl From<MeshArrays> for MeshData {
    fn from(arrays: MeshArrays) -> Self {
        MeshData {
            triangles: arrays.triangle_count() as u32,
            vertices: arrays.vertex_count() as u32,
            arrays,
        }
    }
}

#[wasm_bindgen]
impl MeshData {
    #[wasm_bindgen(js_name = takePositions)]
    pub fn take_positions(&mut self) -> Vec<f32> {
        std::mem::take(&mut self.arrays.positions)
    }
    #[wasm_bindgen(js_name = takeNormals)]
    pub fn take_normals(&mut self) -> Vec<f32> {
        std::mem::take(&mut self.arrays.normals)
    }
    #[wasm_bindgen(js_name = takeIndices)]
    pub fn take_indices(&mut self) -> Vec<u32> {
        std::mem::take(&mut self.arrays.indices)
    }
    #[wasm_bindgen(js_name = takeGroups)]
    pub fn take_groups(&mut self) -> Vec<u32> {
        std::mem::take(&mut self.arrays.groups)
    }
    /// Sharp and boundary curve segments, 6 floats each.
    #[wasm_bindgen(js_name = takeLines)]
    pub fn take_lines(&mut self) -> Vec<f32> {
        std::mem::take(&mut self.arrays.lines)
    }
    #[wasm_bindgen(getter, js_name = triangleCount)]
    pub fn triangle_count(&self) -> u32 {
        self.triangles
    }
    #[wasm_bindgen(getter, js_name = vertexCount)]
    pub fn vertex_count(&self) -> u32 {
        self.vertices
    }
}

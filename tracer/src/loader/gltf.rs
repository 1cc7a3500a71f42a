//! A validated glTF document, with its buffers loaded, into a [`Scene`]: nodes, the default
//! scene's roots, materials and the textures they use, meshes (triangles only), cameras,
//! punctual lights, and the features the scene needs.

use std::borrow::Cow;
use std::collections::HashMap;

use glam::{DMat4, DQuat, DVec3, Vec2, Vec3, Vec4};
use gltf::json::Value;
use gltf::mesh::Mode;
use gltf::Semantic;
use rayon::prelude::*;

use super::accessor::{read_floats, read_indices, view_bytes, Floats};
use super::container::Resolver;
use super::error::{mesh_label, Element, SceneError};
use super::framing::for_each_node_instance;
use super::{images, tangents, SUPPORTED_EXTENSIONS};
use crate::camera::Projection;
use crate::light::PunctualLight;
use crate::material::{AlphaMode, Material};
use crate::scene::{CameraDef, Features, Mesh, Node, Primitive, Scene};
use crate::texture::{Filter, Texture, TextureRef, UvTransform, Wrap};

use gltf::accessor::Dimensions as D;

/// What the conversion reads from.
pub(crate) struct Input<'a> {
    /// The validated document.
    pub doc: &'a gltf::Document,
    /// The same JSON, untyped, for what the `gltf` crate does not expose without its
    /// `extensions` feature (KHR_texture_transform on a normal texture).
    pub raw: &'a Value,
    /// Buffer bytes, one per `buffers[i]`, each cut to its byteLength.
    pub buffers: &'a [Cow<'a, [u8]>],
    /// Where image URIs are looked up.
    pub resolver: Resolver<'a>,
}

/// Converts the document.
pub(crate) fn build(input: &Input<'_>) -> Result<Scene, SceneError> {
    let doc = input.doc;
    let mut warnings = Vec::new();
    for ext in doc.extensions_used() {
        if !SUPPORTED_EXTENSIONS.contains(&ext) {
            warnings.push(format!(
                "optional extension '{ext}' is not supported; ignored"
            ));
        }
    }
    for view in doc.views() {
        view_bytes(&view, input.buffers)?;
    }

    let nodes = convert_nodes(doc, &mut warnings)?;
    let roots = default_roots(doc, &nodes);

    // Materials first: meshes need to know which primitives carry normal maps.
    let mut table = TextureTable::default();
    let mut materials = Vec::with_capacity(doc.materials().len() + 1);
    for m in doc.materials() {
        materials.push(convert_material(&m, input.raw, &mut table, &mut warnings)?);
    }
    let textures = table.decode(input)?;
    let default_material = materials.len() as u32;

    let gltf_meshes: Vec<gltf::Mesh<'_>> = doc.meshes().collect();
    let built: Vec<Result<MeshOut, SceneError>> = gltf_meshes
        .par_iter()
        .map(|m| convert_mesh(m, input.buffers, &materials, default_material))
        .collect();
    let mut meshes = Vec::with_capacity(built.len());
    let mut uses_default = false;
    for out in built {
        let out = out?;
        warnings.extend(out.warnings);
        uses_default |= out.uses_default;
        meshes.push(out.mesh);
    }
    if uses_default {
        materials.push(Material::default());
    }

    let cameras = doc
        .cameras()
        .map(|c| convert_camera(&c))
        .collect::<Result<Vec<_>, _>>()?;
    let mut lights = Vec::new();
    if let Some(ls) = doc.lights() {
        for l in ls {
            lights.push(convert_light(&l, &mut warnings)?);
        }
    }

    let mut scene = Scene {
        nodes,
        roots,
        meshes,
        materials,
        textures,
        cameras,
        lights,
        environment: Default::default(),
        features: Features::default(),
        warnings,
    };
    scene.features = features(&scene);
    let mut drawn = 0u64;
    for_each_node_instance(&scene, |i, _| {
        if let Some(m) = scene.nodes[i as usize].mesh {
            drawn += scene.meshes[m as usize].triangle_count() as u64;
        }
    });
    if drawn == 0 {
        scene
            .warnings
            .push("the default scene draws no triangles".into());
    }
    Ok(scene)
}

// ---------------------------------------------------------------------------------------
// Nodes and scenes

fn convert_nodes(
    doc: &gltf::Document,
    warnings: &mut Vec<String>,
) -> Result<Vec<Node>, SceneError> {
    let mut nodes = Vec::with_capacity(doc.nodes().len());
    for n in doc.nodes() {
        let element = Element::Node(n.index());
        let local = match n.transform() {
            gltf::scene::Transform::Matrix { matrix } => {
                DMat4::from_cols_array_2d(&matrix.map(|c| c.map(f64::from)))
            }
            gltf::scene::Transform::Decomposed {
                translation: t,
                rotation: r,
                scale: s,
            } => {
                let q = DQuat::from_xyzw(r[0] as f64, r[1] as f64, r[2] as f64, r[3] as f64);
                // Exporters write quaternions in f32; renormalise in f64 so that composing
                // deep hierarchies adds no scale drift.
                let len = q.length();
                if !(len.is_finite() && len > 0.0) {
                    return Err(SceneError::at(
                        element,
                        format!("rotation {r:?} is not a usable quaternion"),
                    ));
                }
                DMat4::from_scale_rotation_translation(
                    DVec3::from_array(s.map(f64::from)),
                    q / len,
                    DVec3::from_array(t.map(f64::from)),
                )
            }
        };
        if !local.is_finite() {
            return Err(SceneError::at(element, "transform is not finite"));
        }
        nodes.push(Node {
            name: n.name().map(str::to_owned),
            local,
            children: n.children().map(|c| c.index() as u32).collect(),
            mesh: n.mesh().map(|m| m.index() as u32),
            camera: n.camera().map(|c| c.index() as u32),
            light: n.light().map(|l| l.index() as u32),
        });
    }
    check_node_graph(&nodes, warnings)?;
    Ok(nodes)
}

/// Refuses cycles; warns about nodes with two parents (the spec wants strict trees; we
/// draw such a node once per parent).
fn check_node_graph(nodes: &[Node], warnings: &mut Vec<String>) -> Result<(), SceneError> {
    let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
    for (p, n) in nodes.iter().enumerate() {
        for &c in &n.children {
            let c = c as usize;
            match parent[c] {
                Some(other) if other != p => warnings.push(format!(
                    "node {c} has two parents (nodes {other} and {p}); it is drawn under each"
                )),
                _ => parent[c] = Some(p),
            }
        }
    }
    // Iterative depth-first search: 0 = unseen, 1 = on the current path, 2 = done.
    let mut state = vec![0u8; nodes.len()];
    for start in 0..nodes.len() {
        if state[start] != 0 {
            continue;
        }
        let mut stack = vec![(start, 0usize)];
        state[start] = 1;
        while let Some((n, next)) = stack.last_mut() {
            let n = *n;
            if let Some(&c) = nodes[n].children.get(*next) {
                *next += 1;
                let c = c as usize;
                match state[c] {
                    0 => {
                        state[c] = 1;
                        stack.push((c, 0));
                    }
                    1 => {
                        return Err(SceneError::at(
                            Element::Node(n),
                            format!(
                                "child node {c} is also its ancestor: the node graph has a cycle"
                            ),
                        ))
                    }
                    _ => {}
                }
            } else {
                state[n] = 2;
                stack.pop();
            }
        }
    }
    Ok(())
}

/// The `scene` property's scene, else scene 0, else every node without a parent.
fn default_roots(doc: &gltf::Document, nodes: &[Node]) -> Vec<u32> {
    if let Some(s) = doc.default_scene().or_else(|| doc.scenes().next()) {
        return s.nodes().map(|n| n.index() as u32).collect();
    }
    let mut has_parent = vec![false; nodes.len()];
    for n in nodes {
        for &c in &n.children {
            has_parent[c as usize] = true;
        }
    }
    (0..nodes.len() as u32)
        .filter(|&i| !has_parent[i as usize])
        .collect()
}

// ---------------------------------------------------------------------------------------
// Materials and textures

/// The scene's textures: one per distinct (image, sampler settings) that a material uses.
#[derive(Default)]
struct TextureTable {
    index: HashMap<(usize, u8, u8, u8), u32>,
    entries: Vec<(usize, Wrap, Wrap, Filter)>,
}

fn wrap_of(w: gltf::texture::WrappingMode) -> Wrap {
    match w {
        gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
        gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
    }
}

impl TextureTable {
    fn add(&mut self, tex: &gltf::Texture<'_>) -> u32 {
        let s = tex.sampler();
        let (ws, wt) = (wrap_of(s.wrap_s()), wrap_of(s.wrap_t()));
        let filter = match s.mag_filter() {
            Some(gltf::texture::MagFilter::Nearest) => Filter::Nearest,
            _ => Filter::Linear,
        };
        let image = tex.source().index();
        let key = (image, ws as u8, wt as u8, filter as u8);
        let next = self.entries.len() as u32;
        *self.index.entry(key).or_insert_with(|| {
            self.entries.push((image, ws, wt, filter));
            next
        })
    }

    /// Decodes every image the table uses, once each and in parallel.
    fn decode(&self, input: &Input<'_>) -> Result<Vec<Texture>, SceneError> {
        let mut unique: Vec<usize> = self.entries.iter().map(|e| e.0).collect();
        unique.sort_unstable();
        unique.dedup();
        let decoded: Vec<Result<images::Decoded, SceneError>> =
            unique.par_iter().map(|&i| decode_image(input, i)).collect();
        let mut decoded: Vec<Option<images::Decoded>> = decoded
            .into_iter()
            .map(|d| d.map(Some))
            .collect::<Result<_, _>>()?;
        let mut uses_left: HashMap<usize, usize> = HashMap::new();
        for e in &self.entries {
            *uses_left.entry(e.0).or_default() += 1;
        }
        let mut out = Vec::with_capacity(self.entries.len());
        for &(image, wrap_s, wrap_t, filter) in &self.entries {
            let slot = unique
                .binary_search(&image)
                .expect("every entry's image was decoded");
            let left = uses_left.get_mut(&image).expect("counted above");
            *left -= 1;
            // The last texture using an image takes its texels; earlier ones copy them.
            let d = if *left == 0 {
                decoded[slot].take().expect("taken only by the last use")
            } else {
                let d = decoded[slot]
                    .as_ref()
                    .expect("not taken before the last use");
                images::Decoded {
                    width: d.width,
                    height: d.height,
                    texels: d.texels.clone(),
                }
            };
            out.push(Texture {
                width: d.width,
                height: d.height,
                texels: d.texels,
                wrap_s,
                wrap_t,
                filter,
            });
        }
        Ok(out)
    }
}

fn decode_image(input: &Input<'_>, index: usize) -> Result<images::Decoded, SceneError> {
    let element = Element::Image(index);
    let image = input
        .doc
        .images()
        .nth(index)
        .expect("texture sources are validated");
    let (bytes, mime, what): (Cow<'_, [u8]>, Option<String>, String) = match image.source() {
        gltf::image::Source::View { view, mime_type } => (
            Cow::Borrowed(view_bytes(&view, input.buffers)?),
            Some(mime_type.to_owned()),
            format!("bufferView {}", view.index()),
        ),
        gltf::image::Source::Uri { uri, mime_type } => {
            let r = input.resolver.resolve(uri, element)?;
            let what = if uri.starts_with("data:") {
                "data: URI".into()
            } else {
                format!("'{uri}'")
            };
            (
                Cow::Owned(r.bytes),
                mime_type.map(str::to_owned).or(r.mime),
                what,
            )
        }
    };
    images::decode(&bytes, mime.as_deref())
        .map_err(|e| SceneError::at(element, format!("{what}: {e}")))
}

fn uv_transform(offset: [f32; 2], rotation: f32, scale: [f32; 2]) -> UvTransform {
    UvTransform {
        offset: Vec2::from_array(offset),
        rotation,
        scale: Vec2::from_array(scale),
    }
}

fn texture_ref(
    table: &mut TextureTable,
    info: &gltf::texture::Info<'_>,
    context: &str,
    warnings: &mut Vec<String>,
) -> TextureRef {
    let (texcoord, transform) = match info.texture_transform() {
        Some(t) => (
            t.tex_coord().unwrap_or(info.tex_coord()),
            Some(uv_transform(t.offset(), t.rotation(), t.scale())),
        ),
        None => (info.tex_coord(), None),
    };
    finish_ref(
        table,
        &info.texture(),
        texcoord,
        transform,
        context,
        warnings,
    )
}

fn finish_ref(
    table: &mut TextureTable,
    tex: &gltf::Texture<'_>,
    texcoord: u32,
    transform: Option<UvTransform>,
    context: &str,
    warnings: &mut Vec<String>,
) -> TextureRef {
    if texcoord > 1 {
        warnings.push(format!(
            "{context} reads TEXCOORD_{texcoord}; only TEXCOORD_0 and TEXCOORD_1 are loaded"
        ));
    }
    // An identity transform is no transform: skip the work per sample.
    let transform = transform.filter(|t| *t != uv_transform([0.0; 2], 0.0, [1.0; 2]));
    TextureRef {
        texture: table.add(tex),
        texcoord,
        transform,
    }
}

/// KHR_texture_transform on a normal texture, read from the raw JSON (the `gltf` crate
/// exposes it only for `textureInfo`). Returns (texCoord override, transform).
fn normal_texture_transform(raw: &Value, material: usize) -> (Option<u32>, Option<UvTransform>) {
    let t = &raw["materials"][material]["normalTexture"]["extensions"]["KHR_texture_transform"];
    if !t.is_object() {
        return (None, None);
    }
    let pair = |v: &Value, d: [f32; 2]| -> [f32; 2] {
        match (v[0].as_f64(), v[1].as_f64()) {
            (Some(a), Some(b)) => [a as f32, b as f32],
            _ => d,
        }
    };
    let offset = pair(&t["offset"], [0.0, 0.0]);
    let scale = pair(&t["scale"], [1.0, 1.0]);
    let rotation = t["rotation"].as_f64().unwrap_or(0.0) as f32;
    let texcoord = t["texCoord"]
        .as_u64()
        .map(|c| c.min(u32::MAX as u64) as u32);
    (texcoord, Some(uv_transform(offset, rotation, scale)))
}

fn convert_material(
    m: &gltf::Material<'_>,
    raw: &Value,
    table: &mut TextureTable,
    warnings: &mut Vec<String>,
) -> Result<Material, SceneError> {
    let index = m.index().expect("document materials have an index");
    let element = Element::Material(index);
    let ctx = |slot: &str| format!("material {index} {slot}");
    let pbr = m.pbr_metallic_roughness();

    let mut out = Material {
        name: m.name().map(str::to_owned),
        base_color: Vec4::from_array(pbr.base_color_factor()),
        metallic: pbr.metallic_factor(),
        roughness: pbr.roughness_factor(),
        emissive: Vec3::from_array(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0),
        ior: m.ior().unwrap_or(1.5),
        alpha_mode: match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask {
                cutoff: m.alpha_cutoff().unwrap_or(0.5),
            },
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        },
        double_sided: m.double_sided(),
        ..Material::default()
    };
    out.base_color_texture = pbr
        .base_color_texture()
        .map(|i| texture_ref(table, &i, &ctx("baseColorTexture"), warnings));
    out.metallic_roughness_texture = pbr
        .metallic_roughness_texture()
        .map(|i| texture_ref(table, &i, &ctx("metallicRoughnessTexture"), warnings));
    out.emissive_texture = m
        .emissive_texture()
        .map(|i| texture_ref(table, &i, &ctx("emissiveTexture"), warnings));
    if let Some(n) = m.normal_texture() {
        let (cover, transform) = normal_texture_transform(raw, index);
        let texcoord = cover.unwrap_or(n.tex_coord());
        out.normal_texture = Some(finish_ref(
            table,
            &n.texture(),
            texcoord,
            transform,
            &ctx("normalTexture"),
            warnings,
        ));
        out.normal_scale = n.scale();
    }
    if let Some(s) = m.specular() {
        out.specular = s.specular_factor();
        out.specular_color = Vec3::from_array(s.specular_color_factor());
        out.specular_texture = s
            .specular_texture()
            .map(|i| texture_ref(table, &i, &ctx("specularTexture"), warnings));
        out.specular_color_texture = s
            .specular_color_texture()
            .map(|i| texture_ref(table, &i, &ctx("specularColorTexture"), warnings));
    }
    if let Some(t) = m.transmission() {
        out.transmission = t.transmission_factor();
        out.transmission_texture = t
            .transmission_texture()
            .map(|i| texture_ref(table, &i, &ctx("transmissionTexture"), warnings));
    }

    // A NaN factor would reach every pixel the material covers: refuse it here.
    let cutoff = match out.alpha_mode {
        AlphaMode::Mask { cutoff } => cutoff,
        _ => 0.5,
    };
    let factors = [
        ("baseColorFactor", out.base_color.to_array().to_vec()),
        ("metallicFactor", vec![out.metallic]),
        ("roughnessFactor", vec![out.roughness]),
        (
            "emissive (factor × strength)",
            out.emissive.to_array().to_vec(),
        ),
        ("normalTexture.scale", vec![out.normal_scale]),
        ("ior", vec![out.ior]),
        ("specularFactor", vec![out.specular]),
        (
            "specularColorFactor",
            out.specular_color.to_array().to_vec(),
        ),
        ("transmissionFactor", vec![out.transmission]),
        ("alphaCutoff", vec![cutoff]),
    ];
    for (name, values) in factors {
        if values.iter().any(|v| !v.is_finite()) {
            return Err(SceneError::at(
                element,
                format!("{name} {values:?} is not finite"),
            ));
        }
    }
    if out.emissive.min_element() < 0.0 {
        return Err(SceneError::at(
            element,
            format!("emissive {} is negative", out.emissive),
        ));
    }
    // Factors outside the spec's ranges are clamped, as renderers commonly do.
    out.base_color = out.base_color.clamp(Vec4::ZERO, Vec4::ONE);
    out.metallic = out.metallic.clamp(0.0, 1.0);
    out.roughness = out.roughness.clamp(0.0, 1.0);
    out.transmission = out.transmission.clamp(0.0, 1.0);
    out.specular = out.specular.max(0.0);
    out.specular_color = out.specular_color.max(Vec3::ZERO);
    Ok(out)
}

// ---------------------------------------------------------------------------------------
// Meshes

struct MeshOut {
    mesh: Mesh,
    warnings: Vec<String>,
    uses_default: bool,
}

fn convert_mesh(
    mesh: &gltf::Mesh<'_>,
    buffers: &[Cow<'_, [u8]>],
    materials: &[Material],
    default_material: u32,
) -> Result<MeshOut, SceneError> {
    let label = mesh_label(mesh.index(), mesh.name());
    let mut warnings = Vec::new();
    let mut primitives = Vec::new();
    let mut uses_default = false;
    for (p, prim) in mesh.primitives().enumerate() {
        let where_ = format!("{label}, primitive {p}");
        let material = match prim.material().index() {
            Some(i) => i as u32,
            None => {
                uses_default = true;
                default_material
            }
        };
        let normal_texcoord = materials
            .get(material as usize)
            .and_then(|m| m.normal_texture.as_ref())
            .map(|t| t.texcoord as usize);
        if let Some(out) = convert_primitive(
            &prim,
            buffers,
            material,
            normal_texcoord,
            &where_,
            &mut warnings,
        )? {
            primitives.push(out);
        }
    }
    // Keep a primitive-less mesh anyway so that mesh indices stay the document's.
    let mesh = Mesh::new(mesh.name().map(str::to_owned), primitives);
    Ok(MeshOut {
        mesh,
        warnings,
        uses_default,
    })
}

fn vec3s(f: &Floats) -> Vec<Vec3> {
    f.values
        .chunks_exact(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect()
}

/// Reads attribute `sem` when present, checking its type and that it has one element per
/// vertex.
fn attribute(
    prim: &gltf::Primitive<'_>,
    sem: &Semantic,
    allowed: &[D],
    buffers: &[Cow<'_, [u8]>],
    vertices: usize,
    where_: &str,
) -> Result<Option<Floats>, SceneError> {
    let Some(acc) = prim.get(sem) else {
        return Ok(None);
    };
    let what = format!("{sem:?} in {where_}");
    let f = read_floats(&acc, buffers, allowed, &what)?;
    if f.count() != vertices {
        return Err(SceneError::at(
            Element::Accessor(acc.index()),
            format!(
                "{what} has {} elements but POSITION has {vertices}",
                f.count()
            ),
        ));
    }
    Ok(Some(f))
}

/// One glTF primitive as triangles, or `None` (with a warning) when it draws none.
fn convert_primitive(
    prim: &gltf::Primitive<'_>,
    buffers: &[Cow<'_, [u8]>],
    material: u32,
    normal_texcoord: Option<usize>,
    where_: &str,
    warnings: &mut Vec<String>,
) -> Result<Option<Primitive>, SceneError> {
    let mode = prim.mode();
    if !matches!(
        mode,
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
    ) {
        warnings.push(format!(
            "{where_}: {mode:?} primitives are not rendered; skipped"
        ));
        return Ok(None);
    }
    let Some(pos_acc) = prim.get(&Semantic::Positions) else {
        warnings.push(format!("{where_}: no POSITION attribute; skipped"));
        return Ok(None);
    };
    let positions = vec3s(&read_floats(
        &pos_acc,
        buffers,
        &[D::Vec3],
        &format!("POSITION in {where_}"),
    )?);
    if let Some(v) = positions.iter().position(|p| !p.is_finite()) {
        return Err(SceneError::at(
            Element::Accessor(pos_acc.index()),
            format!("position {v} ({}) is not finite in {where_}", positions[v]),
        ));
    }
    let n = positions.len();

    // Indices, checked against the vertex count, then assembled into triangles.
    let flat: Vec<u32> = match prim.indices() {
        Some(acc) => {
            let idx = read_indices(&acc, buffers, where_)?;
            if let Some(&bad) = idx.iter().find(|&&i| i as usize >= n) {
                return Err(SceneError::at(
                    Element::Accessor(acc.index()),
                    format!("index {bad} out of range for {n} vertices in {where_}"),
                ));
            }
            idx
        }
        None => {
            if n > u32::MAX as usize {
                return Err(SceneError::at(
                    Element::Accessor(pos_acc.index()),
                    format!("{n} vertices is more than 32-bit indices reach in {where_}"),
                ));
            }
            (0..n as u32).collect()
        }
    };
    let indices = assemble(mode, &flat, where_, warnings);

    let mut out = Primitive {
        positions,
        indices,
        material,
        ..Primitive::default()
    };
    if let Some(f) = attribute(prim, &Semantic::Normals, &[D::Vec3], buffers, n, where_)? {
        out.normals = vec3s(&f);
        repair_normals(&mut out, where_, warnings);
    }
    for set in 0..2 {
        if let Some(f) = attribute(
            prim,
            &Semantic::TexCoords(set),
            &[D::Vec2],
            buffers,
            n,
            where_,
        )? {
            out.uvs[set as usize] = f
                .values
                .chunks_exact(2)
                .map(|c| Vec2::new(c[0], c[1]))
                .collect();
        }
    }
    if let Some(f) = attribute(
        prim,
        &Semantic::Colors(0),
        &[D::Vec3, D::Vec4],
        buffers,
        n,
        where_,
    )? {
        out.colors = match f.components {
            3 => f
                .values
                .chunks_exact(3)
                .map(|c| Vec4::new(c[0], c[1], c[2], 1.0))
                .collect(),
            _ => f.values.chunks_exact(4).map(Vec4::from_slice).collect(),
        };
    }
    // TANGENT counts only with NORMAL beside it: without normals the spec asks for flat
    // normals and for supplied tangents to be ignored.
    let mut tangents_ok = false;
    if let Some(f) = attribute(prim, &Semantic::Tangents, &[D::Vec4], buffers, n, where_)? {
        if !out.normals.is_empty() {
            let raw: Vec<Vec4> = f.values.chunks_exact(4).map(Vec4::from_slice).collect();
            tangents_ok = raw
                .iter()
                .all(|t| t.is_finite() && t.truncate().length_squared() > 0.0);
            if tangents_ok {
                out.tangents = raw
                    .iter()
                    .map(|&t| tangents::normalize_tangent(t, Vec3::X))
                    .collect();
            } else {
                warnings.push(format!(
                    "{where_}: TANGENT has zero or non-finite vectors; regenerated"
                ));
            }
        }
    }
    if let Some(set) = normal_texcoord {
        if !tangents_ok {
            need_tangents(&mut out, set, where_, warnings);
        }
    }
    Ok(Some(out))
}

/// Triangles from a flat index list: lists in threes, strips and fans as the spec says.
fn assemble(mode: Mode, v: &[u32], where_: &str, warnings: &mut Vec<String>) -> Vec<[u32; 3]> {
    match mode {
        Mode::TriangleStrip => (0..v.len().saturating_sub(2))
            .map(|i| {
                // Every other triangle swaps two corners to keep the winding.
                if i % 2 == 0 {
                    [v[i], v[i + 1], v[i + 2]]
                } else {
                    [v[i], v[i + 2], v[i + 1]]
                }
            })
            .collect(),
        Mode::TriangleFan => (1..v.len().saturating_sub(1))
            .map(|i| [v[i], v[i + 1], v[0]])
            .collect(),
        _ => {
            let extra = v.len() % 3;
            if extra > 0 {
                warnings.push(format!(
                    "{where_}: {} indices is not a multiple of 3; the last {extra} ignored",
                    v.len()
                ));
            }
            v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
        }
    }
}

/// Renormalises normals; zero or non-finite ones become the area-weighted normal of the
/// faces around the vertex (+Z for a vertex no face gives one).
fn repair_normals(prim: &mut Primitive, where_: &str, warnings: &mut Vec<String>) {
    let mut bad = Vec::new();
    for (i, nrm) in prim.normals.iter_mut().enumerate() {
        match nrm.try_normalize() {
            Some(u) => *nrm = u,
            None => bad.push(i),
        }
    }
    if bad.is_empty() {
        return;
    }
    let mut sum = vec![Vec3::ZERO; prim.positions.len()];
    for &[a, b, c] in &prim.indices {
        let p = |i: u32| prim.positions[i as usize];
        let face = (p(b) - p(a)).cross(p(c) - p(a));
        for i in [a, b, c] {
            sum[i as usize] += face;
        }
    }
    for &i in &bad {
        prim.normals[i] = sum[i].try_normalize().unwrap_or(Vec3::Z);
    }
    warnings.push(format!(
        "{where_}: {} zero or non-finite normals replaced by face normals",
        bad.len()
    ));
}

/// Generates MikkTSpace tangents for a normal-mapped primitive, first giving it flat
/// normals if it has none.
fn need_tangents(prim: &mut Primitive, set: usize, where_: &str, warnings: &mut Vec<String>) {
    if set > 1 || prim.uvs[set].is_empty() {
        warnings.push(format!(
            "{where_}: normal map reads TEXCOORD_{set}, which the primitive lacks; \
             no tangents generated"
        ));
        return;
    }
    if prim.normals.is_empty() {
        unweld_with_flat_normals(prim);
    }
    match tangents::generate(prim, set) {
        Ok(_) => {}
        Err(e) => {
            prim.tangents.clear();
            warnings.push(format!("{where_}: {e}; no tangents generated"));
        }
    }
}

/// Gives every triangle its own three vertices with the face normal: the flat shading
/// the spec asks for when NORMAL is absent, made explicit so tangents can be generated.
fn unweld_with_flat_normals(prim: &mut Primitive) {
    let tris = std::mem::take(&mut prim.indices);
    let pick = |src: &[Vec2]| -> Vec<Vec2> {
        if src.is_empty() {
            Vec::new()
        } else {
            tris.iter().flatten().map(|&i| src[i as usize]).collect()
        }
    };
    let uvs = [pick(&prim.uvs[0]), pick(&prim.uvs[1])];
    let colors = if prim.colors.is_empty() {
        Vec::new()
    } else {
        tris.iter()
            .flatten()
            .map(|&i| prim.colors[i as usize])
            .collect()
    };
    let mut positions = Vec::with_capacity(tris.len() * 3);
    let mut normals = Vec::with_capacity(tris.len() * 3);
    for &[a, b, c] in &tris {
        let (pa, pb, pc) = (
            prim.positions[a as usize],
            prim.positions[b as usize],
            prim.positions[c as usize],
        );
        let nrm = (pb - pa).cross(pc - pa).try_normalize().unwrap_or(Vec3::Z);
        positions.extend([pa, pb, pc]);
        normals.extend([nrm; 3]);
    }
    prim.indices = (0..tris.len() as u32)
        .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
        .collect();
    prim.positions = positions;
    prim.normals = normals;
    prim.uvs = uvs;
    prim.colors = colors;
    prim.tangents.clear();
}

// ---------------------------------------------------------------------------------------
// Cameras and lights

fn convert_camera(c: &gltf::Camera<'_>) -> Result<CameraDef, SceneError> {
    let element = Element::Camera(c.index());
    let projection = match c.projection() {
        gltf::camera::Projection::Perspective(p) => {
            let (yfov, znear) = (p.yfov(), p.znear());
            if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f32::consts::PI) {
                return Err(SceneError::at(
                    element,
                    format!("yfov {yfov} is not in (0, π)"),
                ));
            }
            if !(znear.is_finite() && znear > 0.0) {
                return Err(SceneError::at(
                    element,
                    format!("znear {znear} is not positive"),
                ));
            }
            let aspect_ratio = p.aspect_ratio().filter(|a| a.is_finite() && *a > 0.0);
            Projection::Perspective {
                yfov,
                aspect_ratio,
                znear,
            }
        }
        gltf::camera::Projection::Orthographic(o) => {
            let (xmag, ymag, znear) = (o.xmag(), o.ymag(), o.znear());
            if ![xmag, ymag].iter().all(|m| m.is_finite() && *m != 0.0) {
                return Err(SceneError::at(
                    element,
                    format!("xmag {xmag} and ymag {ymag} must be finite and non-zero"),
                ));
            }
            if !(znear.is_finite() && znear >= 0.0) {
                return Err(SceneError::at(
                    element,
                    format!("znear {znear} is negative"),
                ));
            }
            Projection::Orthographic {
                xmag: xmag.abs(),
                ymag: ymag.abs(),
                znear,
            }
        }
    };
    Ok(CameraDef {
        name: c.name().map(str::to_owned),
        projection,
    })
}

fn convert_light(
    l: &gltf::khr_lights_punctual::Light<'_>,
    warnings: &mut Vec<String>,
) -> Result<PunctualLight, SceneError> {
    let element = Element::Light(l.index());
    let color = Vec3::from_array(l.color());
    let value = color * l.intensity();
    if !value.is_finite() || value.min_element() < 0.0 {
        return Err(SceneError::at(
            element,
            format!(
                "colour {color} × intensity {} is not a finite, non-negative value",
                l.intensity()
            ),
        ));
    }
    let range = match l.range() {
        Some(r) if !(r.is_finite() && r > 0.0) => {
            return Err(SceneError::at(
                element,
                format!("range {r} is not positive"),
            ))
        }
        r => r,
    };
    Ok(match l.kind() {
        gltf::khr_lights_punctual::Kind::Directional => {
            PunctualLight::Directional { illuminance: value }
        }
        gltf::khr_lights_punctual::Kind::Point => PunctualLight::Point {
            intensity: value,
            range,
        },
        gltf::khr_lights_punctual::Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            if !(inner_cone_angle.is_finite() && outer_cone_angle.is_finite()) {
                return Err(SceneError::at(element, "cone angles are not finite"));
            }
            // The spec wants 0 <= inner < outer <= π/2.
            let outer = outer_cone_angle.clamp(1e-4, std::f32::consts::FRAC_PI_2);
            let inner = inner_cone_angle.clamp(0.0, outer);
            if (inner, outer) != (inner_cone_angle, outer_cone_angle) {
                warnings.push(format!(
                    "{element}: cone angles ({inner_cone_angle}, {outer_cone_angle}) clamped to ({inner}, {outer})"
                ));
            }
            PunctualLight::Spot {
                intensity: value,
                range,
                inner_cone: inner,
                outer_cone: outer,
            }
        }
    })
}

// ---------------------------------------------------------------------------------------
// Features

/// What the default scene needs: only materials and lights its node trees reach count.
/// Alpha BLEND counts as `alpha_mask` too, since the tracer renders it as stochastic
/// coverage, which needs the same any-hit alpha test.
fn features(scene: &Scene) -> Features {
    let mut f = Features::default();
    let mut seen_mesh = vec![false; scene.meshes.len()];
    for_each_node_instance(scene, |i, _| {
        let node = &scene.nodes[i as usize];
        if node.light.is_some() {
            f.punctual_lights = true;
        }
        let Some(m) = node.mesh else { return };
        if std::mem::replace(&mut seen_mesh[m as usize], true) {
            return;
        }
        for prim in &scene.meshes[m as usize].primitives {
            if prim.indices.is_empty() {
                continue;
            }
            let mat = &scene.materials[prim.material as usize];
            f.textures |= mat.has_textures();
            f.transmission |= mat.transmission > 0.0;
            f.alpha_mask |= !matches!(mat.alpha_mode, AlphaMode::Opaque);
            f.emissive |= mat.is_emissive();
            f.normal_maps |= mat.normal_texture.is_some() && !prim.tangents.is_empty();
        }
    });
    f
}

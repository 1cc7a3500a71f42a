//! Reading accessors into plain vectors, with every byte range checked before anything is
//! allocated: a declared count is trusted only once the bytes behind it are known to exist.
//!
//! The `gltf` crate's own reader is not used: it computes `count - 1` unchecked and skips
//! out-of-range sparse indices silently.

use std::borrow::Cow;

use gltf::accessor::{DataType, Dimensions};

use super::error::{Element, SceneError};

/// Largest accessor, in bytes, that may be materialised without a buffer view behind it
/// (an all-zero or sparse-only accessor): a guard against huge declared counts.
const MAX_VIEWLESS_BYTES: usize = 256 << 20;

/// The bytes of buffer view `view`, checked to lie inside its buffer.
pub(crate) fn view_bytes<'b>(
    view: &gltf::buffer::View<'_>,
    buffers: &'b [Cow<'_, [u8]>],
) -> Result<&'b [u8], SceneError> {
    let buffer = &buffers[view.buffer().index()];
    let (start, len) = (view.offset(), view.length());
    start
        .checked_add(len)
        .and_then(|end| buffer.get(start..end))
        .ok_or_else(|| {
            SceneError::at(
                Element::BufferView(view.index()),
                format!(
                    "bytes {start}..{} lie outside buffer {} ({} bytes)",
                    start as u128 + len as u128,
                    view.buffer().index(),
                    buffer.len()
                ),
            )
        })
}

fn component_size(ty: DataType) -> usize {
    match ty {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

/// One component as f32, normalised integers mapped as the glTF spec says.
fn component(b: &[u8], ty: DataType, normalized: bool) -> f32 {
    match (ty, normalized) {
        (DataType::I8, false) => b[0] as i8 as f32,
        (DataType::I8, true) => (b[0] as i8 as f32 / 127.0).max(-1.0),
        (DataType::U8, false) => b[0] as f32,
        (DataType::U8, true) => b[0] as f32 / 255.0,
        (DataType::I16, false) => i16::from_le_bytes([b[0], b[1]]) as f32,
        (DataType::I16, true) => (i16::from_le_bytes([b[0], b[1]]) as f32 / 32767.0).max(-1.0),
        (DataType::U16, false) => u16::from_le_bytes([b[0], b[1]]) as f32,
        (DataType::U16, true) => u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0,
        (DataType::U32, false) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        (DataType::U32, true) => {
            (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64 / u32::MAX as f64) as f32
        }
        (DataType::F32, _) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
    }
}

/// An unsigned integer component, exactly (indices, sparse indices).
fn unsigned(b: &[u8], ty: DataType) -> Option<u32> {
    match ty {
        DataType::U8 => Some(b[0] as u32),
        DataType::U16 => Some(u16::from_le_bytes([b[0], b[1]]) as u32),
        DataType::U32 => Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        _ => None,
    }
}

/// A strided run of `count` elements of `elem` bytes, checked to fit in its view.
struct Strided<'b> {
    data: &'b [u8],
    stride: usize,
    elem: usize,
}

impl<'b> Strided<'b> {
    /// Checks that `count` elements of `elem` bytes, `stride` apart from `offset`, fit in
    /// `view_bytes`; `what` names the run in the error.
    #[allow(clippy::too_many_arguments)]
    fn new(
        view: usize,
        view_bytes: &'b [u8],
        offset: usize,
        stride: usize,
        elem: usize,
        count: usize,
        element: Element,
        what: &str,
    ) -> Result<Self, SceneError> {
        if count == 0 {
            return Ok(Self {
                data: &[],
                stride,
                elem,
            });
        }
        let end = stride
            .checked_mul(count - 1)
            .and_then(|s| s.checked_add(elem))
            .and_then(|s| s.checked_add(offset));
        match end {
            Some(end) if end <= view_bytes.len() => Ok(Self {
                data: &view_bytes[offset..end],
                stride,
                elem,
            }),
            _ => Err(SceneError::at(
                element,
                format!(
                    "{what}: {count} elements of {elem} bytes, {stride} apart from byte {offset}, \
                     overrun bufferView {view} ({} bytes)",
                    view_bytes.len()
                ),
            )),
        }
    }

    fn get(&self, i: usize) -> &'b [u8] {
        let at = i * self.stride;
        &self.data[at..at + self.elem]
    }
}

/// An accessor read as f32 components.
pub(crate) struct Floats {
    /// `count × components` values, element after element.
    pub values: Vec<f32>,
    /// Components per element (1 for SCALAR, 2 for VEC2, ...).
    pub components: usize,
}

impl Floats {
    /// Number of elements.
    pub fn count(&self) -> usize {
        self.values.len() / self.components.max(1)
    }
}

fn dims_components(d: Dimensions) -> usize {
    match d {
        Dimensions::Scalar => 1,
        Dimensions::Vec2 => 2,
        Dimensions::Vec3 => 3,
        Dimensions::Vec4 => 4,
        Dimensions::Mat2 => 4,
        Dimensions::Mat3 => 9,
        Dimensions::Mat4 => 16,
    }
}

fn dims_name(d: Dimensions) -> &'static str {
    match d {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    }
}

/// Reads a vector or scalar accessor whose type is one of `allowed`, as f32 (integers
/// normalised when the accessor says so). `what` names its use ("POSITION in mesh 'Body',
/// primitive 0").
pub(crate) fn read_floats(
    acc: &gltf::Accessor<'_>,
    buffers: &[Cow<'_, [u8]>],
    allowed: &[Dimensions],
    what: &str,
) -> Result<Floats, SceneError> {
    let element = Element::Accessor(acc.index());
    let dims = acc.dimensions();
    if !allowed.contains(&dims) {
        let names: Vec<_> = allowed.iter().map(|&d| dims_name(d)).collect();
        return Err(SceneError::at(
            element,
            format!(
                "type {} for {what}, expected {}",
                dims_name(dims),
                names.join(" or ")
            ),
        ));
    }
    let n = dims_components(dims);
    let (ty, normalized) = (acc.data_type(), acc.normalized());
    let csize = component_size(ty);
    let count = acc.count();
    let mut values = dense(
        acc,
        buffers,
        n * csize,
        element,
        what,
        |bytes, out: &mut Vec<f32>| {
            for c in 0..n {
                out.push(component(&bytes[c * csize..], ty, normalized));
            }
        },
    )?;
    if let Some(sparse) = acc.sparse() {
        let indices = sparse_indices(acc, &sparse, buffers, count, element)?;
        let view = sparse.values().view();
        let vb = view_bytes(&view, buffers)?;
        let run = Strided::new(
            view.index(),
            vb,
            sparse.values().offset(),
            n * csize,
            n * csize,
            indices.len(),
            element,
            "sparse values",
        )?;
        for (k, &i) in indices.iter().enumerate() {
            let bytes = run.get(k);
            for c in 0..n {
                values[i as usize * n + c] = component(&bytes[c * csize..], ty, normalized);
            }
        }
    }
    Ok(Floats {
        values,
        components: n,
    })
}

/// Reads an index accessor: SCALAR, unsigned byte, short or int, not normalised.
pub(crate) fn read_indices(
    acc: &gltf::Accessor<'_>,
    buffers: &[Cow<'_, [u8]>],
    what: &str,
) -> Result<Vec<u32>, SceneError> {
    let element = Element::Accessor(acc.index());
    let ty = acc.data_type();
    if acc.dimensions() != Dimensions::Scalar
        || !matches!(ty, DataType::U8 | DataType::U16 | DataType::U32)
    {
        return Err(SceneError::at(
            element,
            format!(
                "indices for {what} must be SCALAR unsigned byte, short or int, not {} {:?}",
                dims_name(acc.dimensions()),
                ty
            ),
        ));
    }
    let csize = component_size(ty);
    let mut values = dense(
        acc,
        buffers,
        csize,
        element,
        what,
        |bytes, out: &mut Vec<u32>| out.push(unsigned(bytes, ty).unwrap_or(0)),
    )?;
    if let Some(sparse) = acc.sparse() {
        let indices = sparse_indices(acc, &sparse, buffers, acc.count(), element)?;
        let view = sparse.values().view();
        let vb = view_bytes(&view, buffers)?;
        let run = Strided::new(
            view.index(),
            vb,
            sparse.values().offset(),
            csize,
            csize,
            indices.len(),
            element,
            "sparse values",
        )?;
        for (k, &i) in indices.iter().enumerate() {
            values[i as usize] = unsigned(run.get(k), ty).unwrap_or(0);
        }
    }
    Ok(values)
}

/// The dense part of an accessor: its buffer view's elements, or zeros when it has none.
fn dense<T: Default + Clone>(
    acc: &gltf::Accessor<'_>,
    buffers: &[Cow<'_, [u8]>],
    elem: usize,
    element: Element,
    what: &str,
    mut push: impl FnMut(&[u8], &mut Vec<T>),
) -> Result<Vec<T>, SceneError> {
    let count = acc.count();
    let per_elem = elem / component_size(acc.data_type());
    match acc.view() {
        Some(view) => {
            let stride = view.stride().unwrap_or(elem);
            if stride < elem {
                return Err(SceneError::at(
                    element,
                    format!(
                        "bufferView {} has byteStride {stride}, smaller than the {elem}-byte \
                         elements of {what}",
                        view.index()
                    ),
                ));
            }
            let vb = view_bytes(&view, buffers)?;
            let run = Strided::new(
                view.index(),
                vb,
                acc.offset(),
                stride,
                elem,
                count,
                element,
                what,
            )?;
            let mut out = Vec::with_capacity(count * per_elem);
            for i in 0..count {
                push(run.get(i), &mut out);
            }
            Ok(out)
        }
        None => {
            if count.saturating_mul(elem) > MAX_VIEWLESS_BYTES {
                return Err(SceneError::at(
                    element,
                    format!("{count} elements for {what} with no bufferView behind them"),
                ));
            }
            Ok(vec![T::default(); count * per_elem])
        }
    }
}

/// A sparse accessor's indices, checked to be below `count`.
fn sparse_indices(
    acc: &gltf::Accessor<'_>,
    sparse: &gltf::accessor::sparse::Sparse<'_>,
    buffers: &[Cow<'_, [u8]>],
    count: usize,
    element: Element,
) -> Result<Vec<u32>, SceneError> {
    let idx = sparse.indices();
    let ty = match idx.index_type() {
        gltf::accessor::sparse::IndexType::U8 => DataType::U8,
        gltf::accessor::sparse::IndexType::U16 => DataType::U16,
        gltf::accessor::sparse::IndexType::U32 => DataType::U32,
    };
    let size = component_size(ty);
    let view = idx.view();
    let vb = view_bytes(&view, buffers)?;
    let n = sparse.count();
    let run = Strided::new(
        view.index(),
        vb,
        idx.offset(),
        size,
        size,
        n,
        element,
        "sparse indices",
    )?;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let i = unsigned(run.get(k), ty).unwrap_or(0);
        if i as usize >= count {
            return Err(SceneError::at(
                Element::Accessor(acc.index()),
                format!("sparse index {i} out of range for {count} elements"),
            ));
        }
        out.push(i);
    }
    Ok(out)
}

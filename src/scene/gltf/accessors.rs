//! Vertex attributes read as float vectors whatever their component type: float32, or the
//! integer types that `KHR_mesh_quantization` and the core spec allow (glTF 2.0 §3.6.2,
//! "Accessors"; normalized integers map to [0, 1] or [−1, 1] as §3.11's table says,
//! `max(c / 127, −1)` for a signed byte), sparse accessors included.

use gltf::accessor::{DataType, Dimensions, Item, Iter};

use super::Loader;
use crate::error::Result;

/// A normalized integer component as a float (glTF 2.0, "Animations" / "Accessors": the
/// conversions every client implements).
trait Component: Item + Copy {
    fn float(self, normalized: bool) -> f32;
}

macro_rules! component {
    ($t:ty, $scale:expr, $signed:expr) => {
        impl Component for $t {
            #[inline]
            fn float(self, normalized: bool) -> f32 {
                if !normalized {
                    return self as f32;
                }
                let v = self as f32 / $scale;
                if $signed {
                    v.max(-1.0)
                } else {
                    v
                }
            }
        }
    };
}

component!(i8, 127.0, true);
component!(u8, 255.0, false);
component!(i16, 32767.0, true);
component!(u16, 65535.0, false);
component!(u32, 4_294_967_295.0, false);

impl Component for f32 {
    #[inline]
    fn float(self, _: bool) -> f32 {
        self
    }
}

/// The rows of `acc` as `[T; N]`, converted to floats; `None` when they cannot be read.
fn rows<'a, 's, T: Component, const N: usize>(
    acc: &gltf::Accessor<'a>,
    get: impl Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
) -> Option<Vec<[f32; N]>>
where
    [T; N]: Item,
{
    let normalized = acc.normalized();
    let iter = Iter::<[T; N]>::new(acc.clone(), get)?;
    Some(iter.map(|v| v.map(|c| c.float(normalized))).collect())
}

impl Loader<'_> {
    /// Accessor `acc` (named `what` in errors) checked against the dimensions `dims` and the
    /// component types `types`, read as float vectors of `N` components (integers converted as
    /// their `normalized` flag says) and checked finite.
    pub(super) fn vectors<const N: usize>(
        &self,
        acc: &gltf::Accessor,
        what: &str,
        dims: Dimensions,
        types: &[DataType],
    ) -> Result<Vec<[f32; N]>>
    where
        [f32; N]: Item,
        [i8; N]: Item,
        [u8; N]: Item,
        [i16; N]: Item,
        [u16; N]: Item,
        [u32; N]: Item,
    {
        self.check_accessor(acc, what, &[dims], types)?;
        let buffers = &self.buffers;
        let get = |b: gltf::Buffer| buffers.get(b.index()).map(Vec::as_slice);
        let out = match acc.data_type() {
            DataType::F32 => rows::<f32, N>(acc, get),
            DataType::I8 => rows::<i8, N>(acc, get),
            DataType::U8 => rows::<u8, N>(acc, get),
            DataType::I16 => rows::<i16, N>(acc, get),
            DataType::U16 => rows::<u16, N>(acc, get),
            DataType::U32 => rows::<u32, N>(acc, get),
        }
        .ok_or_else(|| {
            self.err(format!(
                "{what}: accessor {} could not be read",
                acc.index()
            ))
        })?;
        if let Some(k) = out.iter().position(|v| v.iter().any(|x| !x.is_finite())) {
            return Err(self.err(format!(
                "{what} accessor {} has a non-finite value at index {k}: {:?}",
                acc.index(),
                out[k]
            )));
        }
        Ok(out)
    }
}

/// The component types a vertex attribute may have (glTF 2.0 §3.7.2.1, with
/// `KHR_mesh_quantization`'s additions): positions and morph displacements are floats or any
/// 8/16-bit integer; normals floats or signed normalized 8/16-bit integers; texture
/// coordinates floats or any 8/16-bit integer.
pub(super) const POSITION_TYPES: &[DataType] = &[
    DataType::F32,
    DataType::I8,
    DataType::U8,
    DataType::I16,
    DataType::U16,
];
pub(super) const NORMAL_TYPES: &[DataType] = &[DataType::F32, DataType::I8, DataType::I16];
pub(super) const TEXCOORD_TYPES: &[DataType] = POSITION_TYPES;

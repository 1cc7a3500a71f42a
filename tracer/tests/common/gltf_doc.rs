//! glTF documents written in tests: one base64 data: URI buffer with the buffer views and
//! accessors that describe it.

use glam::DMat4;

pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// One buffer's bytes with the buffer views and accessors that describe them.
#[derive(Default)]
pub struct Doc {
    pub bin: Vec<u8>,
    pub views: Vec<String>,
    pub accessors: Vec<String>,
}

impl Doc {
    pub fn view(&mut self, bytes: &[u8]) -> usize {
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        self.views.push(format!(
            r#"{{"buffer":0,"byteOffset":{},"byteLength":{}}}"#,
            self.bin.len(),
            bytes.len()
        ));
        self.bin.extend_from_slice(bytes);
        self.views.len() - 1
    }

    pub fn accessor(
        &mut self,
        bytes: &[u8],
        component: u32,
        ty: &str,
        count: usize,
        extra: &str,
    ) -> usize {
        let view = self.view(bytes);
        self.accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":{component},"type":"{ty}","count":{count}{extra}}}"#
        ));
        self.accessors.len() - 1
    }

    pub fn strided_accessor(
        &mut self,
        bytes: &[u8],
        stride: usize,
        component: u32,
        ty: &str,
        count: usize,
        extra: &str,
    ) -> usize {
        let view = self.view(bytes);
        let v = self.views.pop().unwrap();
        self.views
            .push(v.replacen('{', &format!(r#"{{"byteStride":{stride},"#), 1));
        self.accessors.push(format!(
            r#"{{"bufferView":{view},"componentType":{component},"type":"{ty}","count":{count}{extra}}}"#
        ));
        self.accessors.len() - 1
    }

    pub fn floats(&mut self, values: &[f32], ty: &str, per: usize) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, 5126, ty, values.len() / per, "")
    }

    pub fn vec3(&mut self, v: &[[f32; 3]]) -> usize {
        let flat: Vec<f32> = v.iter().flatten().copied().collect();
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in v {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let bytes: Vec<u8> = flat.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(
            &bytes,
            5126,
            "VEC3",
            v.len(),
            &format!(r#","min":{lo:?},"max":{hi:?}"#),
        )
    }

    pub fn vec2(&mut self, v: &[[f32; 2]]) -> usize {
        self.floats(&v.iter().flatten().copied().collect::<Vec<_>>(), "VEC2", 2)
    }

    pub fn raw_accessor(&mut self, json: String) -> usize {
        self.accessors.push(json);
        self.accessors.len() - 1
    }

    pub fn scalars(&mut self, v: &[f32]) -> usize {
        self.floats(v, "SCALAR", 1)
    }

    pub fn vec4(&mut self, v: &[[f32; 4]]) -> usize {
        self.floats(&v.concat(), "VEC4", 4)
    }

    pub fn joints_u8(&mut self, v: &[[u8; 4]]) -> usize {
        self.accessor(&v.concat(), 5121, "VEC4", v.len(), "")
    }

    pub fn mat4s(&mut self, m: &[DMat4]) -> usize {
        let flat: Vec<f32> = m
            .iter()
            .flat_map(|m| m.to_cols_array().map(|v| v as f32))
            .collect();
        self.floats(&flat, "MAT4", 16)
    }

    pub fn u16s(&mut self, v: &[u16]) -> usize {
        let bytes: Vec<u8> = v.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, 5123, "SCALAR", v.len(), "")
    }

    pub fn u32s(&mut self, v: &[u32]) -> usize {
        let bytes: Vec<u8> = v.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, 5125, "SCALAR", v.len(), "")
    }

    pub fn buffer_json(&self) -> String {
        format!(
            r#"[{{"byteLength":{},"uri":"data:application/octet-stream;base64,{}"}}]"#,
            self.bin.len(),
            base64(&self.bin)
        )
    }

    /// The whole document: `rest` holds the other top-level properties, comma-led.
    pub fn json(&self, rest: &str) -> String {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"buffers":{},"bufferViews":[{}],"accessors":[{}]{rest}}}"#,
            self.buffer_json(),
            self.views.join(","),
            self.accessors.join(",")
        )
    }
}

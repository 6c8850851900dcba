//! The scenes the end-to-end tests write, built in one place instead of as inline TOML.
//!
//! A [`SceneToml`] writes the tables in the order they are added, a key a line, numbers as Rust
//! prints them (`2.0`, `0.45`), so that a test reads as the scene it builds:
//!
//! ```text
//! SceneToml::spaced().camera_above(64, 48).floor(&diffuse(&[0.5])).lamp(5.0)
//! ```
//!
//! is [`super::small_room`]: a 2 × 2 floor seen from above, lit by a 0.4 × 0.4 quad light 1.5
//! above it. What the builder does not know (lights that are not
//! surfaces, `[environment]`, `[[group]]`) goes in with [`SceneToml::raw`].

/// A scene file being built; [`SceneToml::to_toml`] gives its text.
#[derive(Clone, Debug)]
pub struct SceneToml {
    text: String,
    spaced: bool,
}

/// A number as the scene files of the tests write it (`5.0`, `0.45`, `-1.0`).
pub fn num(x: f64) -> String {
    format!("{x:?}")
}

/// A vector `[x, y, z]`.
pub fn vec3(v: [f64; 3]) -> String {
    format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]))
}

/// A colour: one number (grey) or `[r, g, b]`.
pub fn colour(c: &[f64]) -> String {
    match c {
        [grey] => num(*grey),
        [r, g, b] => vec3([*r, *g, *b]),
        _ => panic!("a colour is one number or three"),
    }
}

/// `f32` values as the `f64`s they print as (0.2 stays 0.2), for colours a test also checks.
pub fn from_f32<const N: usize>(x: [f32; N]) -> [f64; N] {
    x.map(|v| v.to_string().parse().unwrap())
}

/// An object's `material` line for an inline table written out, e.g.
/// `material(r#"{ type = "mirror", rho_s = 0.8 }"#)`.
pub fn material(table: &str) -> String {
    format!("material = {table}")
}

/// An object's `material` line: Lambert of reflectance `rho`.
pub fn diffuse(rho: &[f64]) -> String {
    material(&format!(
        "{{ type = \"diffuse\", rho_d = {} }}",
        colour(rho)
    ))
}

/// An object's `material` line: an ideal mirror of reflectance `rho`.
pub fn mirror(rho: &[f64]) -> String {
    material(&format!("{{ type = \"mirror\", rho_s = {} }}", colour(rho)))
}

/// An object's `emission` line: an area light of radiance `e`.
pub fn emission(e: &[f64]) -> String {
    format!("emission = {}", colour(e))
}

impl SceneToml {
    /// A scene whose tables are separated by a blank line.
    pub fn spaced() -> Self {
        SceneToml {
            text: "\n".to_string(),
            spaced: true,
        }
    }

    /// A scene whose tables follow each other without a blank line.
    pub fn compact() -> Self {
        SceneToml {
            text: "\n".to_string(),
            spaced: false,
        }
    }

    /// Starts table `header` (`[camera]`, `[[object]]`, …).
    fn header(&mut self, header: &str) {
        if self.spaced && self.text != "\n" {
            self.text.push('\n');
        }
        self.text.push_str(header);
        self.text.push('\n');
    }

    fn line(&mut self, line: &str) {
        if !line.is_empty() {
            self.text.push_str(line);
            self.text.push('\n');
        }
    }

    /// A table of `key = value` lines, the values written as given.
    pub fn table(mut self, header: &str, keys: &[(&str, &str)]) -> Self {
        self.header(header);
        for (k, v) in keys {
            self.line(&format!("{k} = {v}"));
        }
        self
    }

    /// `[render]` with these keys, e.g. `&[("spp", "8"), ("seed", "3")]`.
    pub fn render(self, keys: &[(&str, &str)]) -> Self {
        self.table("[render]", keys)
    }

    /// A look-at `[camera]` of `width` × `height` pixels and a vertical field of view of
    /// `fov_y_deg`.
    pub fn camera(
        self,
        width: u32,
        height: u32,
        eye: [f64; 3],
        target: [f64; 3],
        fov_y_deg: f64,
    ) -> Self {
        self.table(
            "[camera]",
            &[
                ("width", &width.to_string()),
                ("height", &height.to_string()),
                ("eye", &vec3(eye)),
                ("target", &vec3(target)),
                ("fov_y_deg", &num(fov_y_deg)),
            ],
        )
    }

    /// The camera of the small room: from (0, 2, 2) at the origin, 45° vertical field of view.
    pub fn camera_above(self, width: u32, height: u32) -> Self {
        self.camera(width, height, [0.0, 2.0, 2.0], [0.0; 3], 45.0)
    }

    /// An `[[object]]`: its name, group and shape, the shape's keys, then `look` (a
    /// [`diffuse`], [`material`] or [`emission`] line, or "" for none).
    pub fn object(
        mut self,
        name: &str,
        group: &str,
        shape: &str,
        keys: &[(&str, String)],
        look: &str,
    ) -> Self {
        self.header("[[object]]");
        self.line(&format!("name = \"{name}\""));
        self.line(&format!("group = \"{group}\""));
        self.line(&format!("shape = \"{shape}\""));
        for (k, v) in keys {
            self.line(&format!("{k} = {v}"));
        }
        self.line(look);
        self
    }

    /// A quad (parallelogram) with `corner` and edges `u`, `v`; its front side faces u × v.
    pub fn quad(
        self,
        name: &str,
        group: &str,
        corner: [f64; 3],
        u: [f64; 3],
        v: [f64; 3],
        look: &str,
    ) -> Self {
        let keys = [
            ("corner", vec3(corner)),
            ("edge_u", vec3(u)),
            ("edge_v", vec3(v)),
        ];
        self.object(name, group, "quad", &keys, look)
    }

    /// An axis-aligned box from `min` to `max`.
    pub fn cuboid(self, name: &str, group: &str, min: [f64; 3], max: [f64; 3], look: &str) -> Self {
        let keys = [("min", vec3(min)), ("max", vec3(max))];
        self.object(name, group, "box", &keys, look)
    }

    /// A sphere; `segments`, the mesh's divisions around, when not the default.
    pub fn sphere(
        self,
        name: &str,
        group: &str,
        center: [f64; 3],
        radius: f64,
        segments: Option<u32>,
        look: &str,
    ) -> Self {
        let mut keys = vec![("center", vec3(center)), ("radius", num(radius))];
        if let Some(s) = segments {
            keys.push(("segments", s.to_string()));
        }
        self.object(name, group, "sphere", &keys, look)
    }

    /// The small room's floor, group "floor": 2 × 2 at y = 0 around the origin, facing up.
    pub fn floor(self, look: &str) -> Self {
        self.floor_sized(1.0, look)
    }

    /// A floor like [`SceneToml::floor`] of `2 half` × `2 half`.
    pub fn floor_sized(self, half: f64, look: &str) -> Self {
        self.quad(
            "floor",
            "floor",
            [-half, 0.0, half],
            [2.0 * half, 0.0, 0.0],
            [0.0, 0.0, -2.0 * half],
            look,
        )
    }

    /// The small room's lamp, group "lamp": a 0.4 × 0.4 quad light 1.5 above the origin,
    /// facing down, of radiance `e`.
    pub fn lamp(self, e: f64) -> Self {
        self.quad(
            "lamp",
            "lamp",
            [-0.2, 1.5, -0.2],
            [0.4, 0.0, 0.0],
            [0.0, 0.0, 0.4],
            &emission(&[e]),
        )
    }

    /// A floor of ρd (0.2, 0.5, 0.8) seen from above at 24 × 18 pixels with nothing around it,
    /// direct light only (`max_depth` 2): the scene of the tests of light from the open sky,
    /// whose lights a test appends.
    pub fn open_floor() -> Self {
        SceneToml::compact()
            .render(&[("max_depth", "2")])
            .camera(24, 18, [0.0, 1.0, 2.0], [0.0; 3], 60.0)
            .floor(&diffuse(&[0.2, 0.5, 0.8]))
    }

    /// Text appended as it is (lights, `[environment]`, `[[group]]`, …).
    pub fn raw(mut self, text: &str) -> Self {
        self.text.push_str(text);
        self
    }

    /// The scene file's text.
    pub fn to_toml(&self) -> String {
        self.text.clone()
    }
}

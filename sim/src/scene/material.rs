//! Materials: the sourced library and the `"material"` section of a scene file.
//!
//! A material is homogeneous and isotropic (paper Sec. 3): density ρ (kg/m³), specific heat
//! c_p (J/(kg K)), conductivity k (W/(m K)), hence diffusivity α = k/(ρ c_p) (m²/s); plus the
//! long-wave (8–14 µm) emissivity ε that sets radiative loss and what the camera reads, and
//! the absorptivity a of the visible surface for lamp light (absorbed flux = a × irradiance).
//!
//! # Painted surfaces
//! The library models the paper's setup, where objects are painted matte black (Sec. 7):
//! **absorptivity is that of a matte-black painted surface, 0.95, for every entry**, and
//! emissivity is 0.95 (painted) except where the bare material already has a high LWIR
//! emissivity, whose table value is kept (glass, brick, plastics, wood). For bare surfaces,
//! override `emissivity` and `absorptivity` in the scene, e.g.
//! `{"name": "steel", "emissivity": 0.07, "absorptivity": 0.4}`. Bare values from the reference:
//!
//! | material | bare ε (8–14 µm) | bare lamp absorptivity |
//! |---|---|---|
//! | steel | polished 0.07, cold-rolled 0.09, oxidised ≈0.8 | dull/oxidised ≈0.9, galvanised 0.64 |
//! | stainless_steel | polished 0.07, untreated sheet 0.16–0.28 | polished 0.33, pickled 0.52 |
//! | aluminium | 0.03–0.09 (anodised 0.95–0.97) | polished 0.10, clear-anodised 0.14 |
//! | copper | polished 0.03, oxidised 0.76–0.78 | polished 0.18, tarnished 0.64 |
//! | eps | ≈0.60 (white, low confidence) | ≈0.1–0.3, translucent |
//! | polystyrene, pmma, pet, glass (clear) | as in the library | ≈0 visible; ≈0.12–0.21 of a filament lamp's output lies beyond their cut-off |
//! | brick (red) | 0.93 | ≈0.70 |
//! | pine | 0.92 | ≈0.45 |
//! | pvc, pla, abs | as in the library (white ≈0.84, black ≈0.95) | colour-dependent |
//!
//! # Library
//! Room-temperature values; α computed from k, ρ and c_p. Bracketed keys name the sources of
//! the project's physical-parameter reference (section 7), which also lists the ranges; treat
//! k and c_p as ±10–20 %.
//!
//! | name | ρ kg/m³ | c_p J/(kg K) | k W/(m K) | α m²/s | ε | absorptivity | source |
//! |---|---|---|---|---|---|---|---|
//! | polystyrene | 1050 | 1300 | 0.15 | 1.10e-7 | 0.92 | 0.95 | \[R1\]\[C1\]\[T\]\[FL\] solid GPPS |
//! | eps | 20 | 1300 | 0.035 | 1.35e-6 | 0.95 | 0.95 | \[EPS1\]\[EPS2\]\[R1\]\[iR\]\[SA\] white foam |
//! | steel | 7850 | 486 | 51.9 | 1.36e-5 | 0.95 | 0.95 | \[C1\]\[G1\]\[E1\]\[W1\]\[F\]\[T\]\[SA\] carbon steel |
//! | stainless_steel | 8000 | 500 | 16 | 4.00e-6 | 0.95 | 0.95 | \[C1\]\[G1\]\[E1\]\[W1\]\[F\]\[SA\] 304/316 |
//! | glass | 2500 | 840 | 1.0 | 4.76e-7 | 0.94 | 0.95 | \[E1\]\[G1\]\[C1\]\[EC\]\[T\] soda-lime |
//! | brick | 1600 | 840 | 0.70 | 5.21e-7 | 0.93 | 0.95 | \[EC\]\[W1\]\[T\]\[SA\] common clay |
//! | aluminium | 2700 | 896 | 167 | 6.90e-5 | 0.95 | 0.95 | \[AL\]\[W1\]\[F\]\[T\]\[SA\] 6061-T6 |
//! | copper | 8933 | 385 | 401 | 1.17e-4 | 0.95 | 0.95 | \[I1\]\[T\]\[SA\] pure |
//! | pmma | 1190 | 1450 | 0.19 | 1.10e-7 | 0.90 | 0.95 | \[PM\]\[E1\]\[R1\]\[iR\] |
//! | pet | 1370 | 1200 | 0.20 | 1.22e-7 | 0.90 | 0.95 | \[PET\]\[R1\]\[FL\] |
//! | pvc | 1390 | 900 | 0.16 | 1.28e-7 | 0.92 | 0.95 | \[E1\]\[G1\]\[R1\]\[F\]\[iR\]\[T\] rigid |
//! | pla | 1300 | 1500 | 0.13 | 6.67e-8 | 0.90 | 0.95 | \[PLA\]\[iR\] solid filament |
//! | abs | 1050 | 1400 | 0.20 | 1.36e-7 | 0.90 | 0.95 | \[R1\]\[ABS\]\[iR\] |
//! | pine | 510 | 1350 | 0.12 | 1.74e-7 | 0.92 | 0.95 | \[EC\]\[E1\]\[iR\]\[T\]\[SA\] dry, across grain |
//!
//! Names are case-insensitive, and `-` or a space may stand for `_`. Aliases: `aluminum`
//! (aluminium), `acrylic` (pmma), `soda_lime_glass` (glass), `gpps` (polystyrene),
//! `carbon_steel` (steel), `expanded_polystyrene` (eps). Each entry's
//! [`Material::source`] says which value was chosen where the sources disagree.

use std::sync::OnceLock;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::validate::{num, Check};
use super::SceneError;

/// Absorptivity and emissivity of a matte-black painted surface (paper Sec. 7; black paint
/// 0.95–0.97 \[TF\]\[SC\]\[SA\], painted steel 0.92–0.96).
pub const PAINTED_BLACK: f64 = 0.95;

/// Thermal and optical properties of a homogeneous material (SI); also a dataset's
/// `material.json` (`crate::dataset_format`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Canonical library name, the name given in the scene, or `"custom"`.
    pub name: String,
    /// Density ρ, in kg/m³.
    pub density: f64,
    /// Specific heat capacity c_p, in J/(kg K).
    pub specific_heat: f64,
    /// Thermal conductivity k, in W/(m K).
    pub conductivity: f64,
    /// Hemispherical emissivity ε in the camera's 8–14 µm band, in [0, 1].
    pub emissivity: f64,
    /// Fraction of the lamp irradiance absorbed by the visible surface, in [0, 1].
    pub absorptivity: f64,
    /// Where the numbers come from (reference keys and the choices made).
    pub source: String,
}

impl Material {
    /// Thermal diffusivity α = k/(ρ c_p), in m²/s.
    pub fn diffusivity(&self) -> f64 {
        self.conductivity / (self.density * self.specific_heat)
    }

    /// Volumetric heat capacity ρ c_p, in J/(m³ K).
    pub fn volumetric_heat_capacity(&self) -> f64 {
        self.density * self.specific_heat
    }

    /// Checks every number; JSON paths are `{prefix}.density` etc.
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range.
    pub fn validate(&self, prefix: &str) -> Check {
        check_property(prefix, Property::Density, self.density)?;
        check_property(prefix, Property::SpecificHeat, self.specific_heat)?;
        check_property(prefix, Property::Conductivity, self.conductivity)?;
        check_property(prefix, Property::Emissivity, self.emissivity)?;
        check_property(prefix, Property::Absorptivity, self.absorptivity)
    }
}

#[derive(Clone, Copy)]
enum Property {
    Density,
    SpecificHeat,
    Conductivity,
    Emissivity,
    Absorptivity,
}

impl Property {
    const ALL: [Property; 5] = [
        Property::Density,
        Property::SpecificHeat,
        Property::Conductivity,
        Property::Emissivity,
        Property::Absorptivity,
    ];

    fn field(self) -> &'static str {
        match self {
            Property::Density => "density",
            Property::SpecificHeat => "specific_heat",
            Property::Conductivity => "conductivity",
            Property::Emissivity => "emissivity",
            Property::Absorptivity => "absorptivity",
        }
    }

    fn unit(self) -> &'static str {
        match self {
            Property::Density => "kg/m^3",
            Property::SpecificHeat => "J/(kg K)",
            Property::Conductivity => "W/(m K)",
            Property::Emissivity | Property::Absorptivity => "",
        }
    }

    fn of_spec(self, spec: &MaterialSpec) -> Option<f64> {
        match self {
            Property::Density => spec.density,
            Property::SpecificHeat => spec.specific_heat,
            Property::Conductivity => spec.conductivity,
            Property::Emissivity => spec.emissivity,
            Property::Absorptivity => spec.absorptivity,
        }
    }

    fn of_material(self, m: &mut Material) -> &mut f64 {
        match self {
            Property::Density => &mut m.density,
            Property::SpecificHeat => &mut m.specific_heat,
            Property::Conductivity => &mut m.conductivity,
            Property::Emissivity => &mut m.emissivity,
            Property::Absorptivity => &mut m.absorptivity,
        }
    }
}

fn check_property(prefix: &str, property: Property, value: f64) -> Check {
    let path = format!("{prefix}.{}", property.field());
    let n = num(&path, value, property.unit())?;
    match property {
        Property::Emissivity | Property::Absorptivity => n.within(0.0, true, 1.0, true)?,
        _ => n.gt(0.0)?,
    };
    Ok(())
}

/// The `"material"` section: a library name, optionally with per-field overrides, or all five
/// numbers explicitly.
///
/// Resolution ([`MaterialSpec::resolve`]):
/// - all five numbers given: an explicit material; `name` (default `"custom"`) is only a
///   label and the library is not consulted;
/// - otherwise `name` is required and looked up in [`material_library`]; the numbers given
///   replace the library's.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Library name (case-insensitive; see the module docs for names and aliases). Required
    /// unless all five numbers are given (no default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Density ρ, in kg/m³ (> 0); overrides the library (no default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density: Option<f64>,
    /// Specific heat c_p, in J/(kg K) (> 0); overrides the library (no default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub specific_heat: Option<f64>,
    /// Thermal conductivity k, in W/(m K) (> 0); overrides the library (no default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conductivity: Option<f64>,
    /// LWIR emissivity, in [0, 1]; overrides the library (no default; library values model
    /// matte-black paint, 0.95, or the bare value where it is already high).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emissivity: Option<f64>,
    /// Lamp absorptivity of the visible surface, in [0, 1]; overrides the library (no
    /// default; library value 0.95, matte-black paint).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub absorptivity: Option<f64>,
}

impl MaterialSpec {
    /// A spec naming a library material without overrides.
    pub fn named(name: &str) -> Self {
        MaterialSpec { name: Some(name.to_owned()), ..MaterialSpec::default() }
    }

    /// Resolves the spec to a complete, range-checked [`Material`] (JSON paths `material.*`).
    ///
    /// # Errors
    /// - [`SceneError::UnknownMaterial`] if `name` is not in the library (and not all five
    ///   numbers are given);
    /// - [`SceneError::Invalid`] at `material.<field>` with `required when material.name is
    ///   absent` for missing numbers without a name (all missing fields are named), or for a
    ///   number out of range.
    pub fn resolve(&self) -> Result<Material, SceneError> {
        for property in Property::ALL {
            if let Some(value) = property.of_spec(self) {
                check_property("material", property, value)?;
            }
        }
        let given: Vec<&str> = Property::ALL.iter().filter(|p| p.of_spec(self).is_some()).map(|p| p.field()).collect();
        let explicit = given.len() == Property::ALL.len();

        let mut material = match (&self.name, explicit) {
            (name, true) => Material {
                name: name.clone().unwrap_or_else(|| "custom".to_owned()),
                density: 0.0,
                specific_heat: 0.0,
                conductivity: 0.0,
                emissivity: 0.0,
                absorptivity: 0.0,
                source: "explicit values in the scene".to_owned(),
            },
            (Some(name), false) => {
                let mut m = lookup_material(name).ok_or_else(|| unknown_material(name))?;
                if !given.is_empty() {
                    m.source = format!("{}; overridden in the scene: {}", m.source, given.join(", "));
                }
                m
            }
            (None, false) => {
                let missing: Vec<String> = Property::ALL
                    .iter()
                    .filter(|p| p.of_spec(self).is_none())
                    .map(|p| format!("material.{}", p.field()))
                    .collect();
                let mut message = "required when material.name is absent".to_owned();
                if missing.len() > 1 {
                    message.push_str(&format!("; also missing: {}", missing[1..].join(", ")));
                }
                return Err(SceneError::invalid(missing[0].clone(), message));
            }
        };
        for property in Property::ALL {
            if let Some(value) = property.of_spec(self) {
                *property.of_material(&mut material) = value;
            }
        }
        material.validate("material")?;
        Ok(material)
    }
}

fn unknown_material(name: &str) -> SceneError {
    let mut known: Vec<String> = material_library().iter().map(|m| m.name.clone()).collect();
    known.extend(ALIASES.iter().map(|(alias, name)| format!("{alias} (= {name})")));
    SceneError::UnknownMaterial { path: None, name: name.to_owned(), known }
}

/// One library row before it becomes a [`Material`].
struct Entry {
    name: &'static str,
    density: f64,
    specific_heat: f64,
    conductivity: f64,
    emissivity: f64,
    source: &'static str,
}

/// The library rows (see the module docs for the table and the painted-surface convention).
const ENTRIES: &[Entry] = &[
    Entry {
        name: "polystyrene",
        density: 1050.0,
        specific_heat: 1300.0,
        conductivity: 0.15,
        emissivity: 0.92,
        source: "[R1][C1][T][FL] solid GPPS; c_p 1300 and k 0.15 chosen over the alternative \
                 1170 and 0.13; bare eps 0.9-0.95",
    },
    Entry {
        name: "eps",
        density: 20.0,
        specific_heat: 1300.0,
        conductivity: 0.035,
        emissivity: PAINTED_BLACK,
        source: "[EPS1][EPS2][R1][iR][SA] expanded polystyrene foam, rho 20 (14-32), k 0.035 \
                 (0.032-0.040) includes radiation through the cells [EPS2]; bare eps ~0.60 \
                 (low confidence), painted",
    },
    Entry {
        name: "steel",
        density: 7850.0,
        specific_heat: 486.0,
        conductivity: 51.9,
        emissivity: PAINTED_BLACK,
        source: "[C1][G1][E1][W1][F][T][SA] carbon steel ~1020-1025, k 51.9 (45-52): generic \
                 steel alpha 12-14 mm^2/s [G1][E1][C1] rather than AISI 1010's 18.8 [W1]; bare \
                 eps 0.07-0.8 by finish, painted",
    },
    Entry {
        name: "stainless_steel",
        density: 8000.0,
        specific_heat: 500.0,
        conductivity: 16.0,
        emissivity: PAINTED_BLACK,
        source: "[C1][G1][E1][W1][F][SA] 304/316, k 16 (15.9-17); bare eps 0.07-0.28, painted",
    },
    Entry {
        name: "glass",
        density: 2500.0,
        specific_heat: 840.0,
        conductivity: 1.0,
        emissivity: 0.94,
        source: "[E1][G1][C1][EC][T] soda-lime, c_p 840 (750-880); k 1.0 [E1] chosen among \
                 0.8 [EC], 1.05 [G1], 1.7 [C1]; eps 0.94 bare",
    },
    Entry {
        name: "brick",
        density: 1600.0,
        specific_heat: 840.0,
        conductivity: 0.70,
        emissivity: 0.93,
        source: "[EC][W1][T][SA] common clay, rho 1600 (1600-2200); alpha 0.52 mm^2/s \
                 [W1][EC] chosen over 0.28-0.34 [PD]; eps 0.93 bare",
    },
    Entry {
        name: "aluminium",
        density: 2700.0,
        specific_heat: 896.0,
        conductivity: 167.0,
        emissivity: PAINTED_BLACK,
        source: "[AL][W1][F][T][SA] alloy 6061-T6, k 167 (151-202), not pure Al \
                 (2702/903/237 [I1]); bare eps 0.03-0.09, painted",
    },
    Entry {
        name: "copper",
        density: 8933.0,
        specific_heat: 385.0,
        conductivity: 401.0,
        emissivity: PAINTED_BLACK,
        source: "[I1][T][SA] pure copper; bare eps 0.03 polished, 0.76-0.78 oxidised, painted",
    },
    Entry {
        name: "pmma",
        density: 1190.0,
        specific_heat: 1450.0,
        conductivity: 0.19,
        emissivity: 0.90,
        source: "[PM][E1][R1][iR] acrylic, c_p 1450 (1260-1500), k 0.19 (0.17-0.20); eps 0.9 \
                 (0.86-0.94)",
    },
    Entry {
        name: "pet",
        density: 1370.0,
        specific_heat: 1200.0,
        conductivity: 0.20,
        emissivity: 0.90,
        source: "[PET][R1][FL] compromise between 1370/1000/0.24 and the Ashby-style \
                 1290-1400/1420-1470/0.138-0.151 [PET]; eps ~0.9 (generic plastic)",
    },
    Entry {
        name: "pvc",
        density: 1390.0,
        specific_heat: 900.0,
        conductivity: 0.16,
        emissivity: 0.92,
        source: "[E1][G1][R1][F][iR][T] rigid PVC; alpha 0.13 mm^2/s from [E1][G1][R1] chosen \
                 over 0.08 [W1]; eps 0.92 (0.91-0.94)",
    },
    Entry {
        name: "pla",
        density: 1300.0,
        specific_heat: 1500.0,
        conductivity: 0.13,
        emissivity: 0.90,
        source: "[PLA][iR] solid FDM filament; c_p 1500 between 1800 (makeitfrom) and 1200 \
                 (measured on prints, Zmeskal); infill lowers effective rho and k; eps ~0.9",
    },
    Entry {
        name: "abs",
        density: 1050.0,
        specific_heat: 1400.0,
        conductivity: 0.20,
        emissivity: 0.90,
        source: "[R1][ABS][iR] c_p 1400 (1300-1470), k 0.20 (0.17-0.25); eps ~0.9",
    },
    Entry {
        name: "pine",
        density: 510.0,
        specific_heat: 1350.0,
        conductivity: 0.12,
        emissivity: 0.92,
        source: "[EC][E1][iR][T][SA] dry pine across the grain; alpha 0.17 mm^2/s [EC][E1] \
                 chosen over 0.082 (yellow pine) [W1]; eps 0.92 (0.90-0.94)",
    },
];

/// Accepted aliases, as (alias, canonical name).
const ALIASES: &[(&str, &str)] = &[
    ("aluminum", "aluminium"),
    ("acrylic", "pmma"),
    ("soda_lime_glass", "glass"),
    ("gpps", "polystyrene"),
    ("carbon_steel", "steel"),
    ("expanded_polystyrene", "eps"),
];

/// The material library, in the order of the module-level table.
pub fn material_library() -> &'static [Material] {
    static LIBRARY: OnceLock<Vec<Material>> = OnceLock::new();
    LIBRARY.get_or_init(|| {
        ENTRIES
            .iter()
            .map(|e| Material {
                name: e.name.to_owned(),
                density: e.density,
                specific_heat: e.specific_heat,
                conductivity: e.conductivity,
                emissivity: e.emissivity,
                absorptivity: PAINTED_BLACK,
                source: e.source.to_owned(),
            })
            .collect()
    })
}

/// Looks a material up by name or alias: case-insensitive, with `-` or a space standing for
/// `_` (`"Stainless Steel"`, `"aluminum"`). Returns the entry under its canonical name.
pub fn lookup_material(name: &str) -> Option<Material> {
    let key: String = name
        .trim()
        .chars()
        .map(|c| match c {
            '-' | ' ' => '_',
            c => c.to_ascii_lowercase(),
        })
        .collect();
    let canonical = ALIASES.iter().find(|(alias, _)| *alias == key).map_or(key.as_str(), |(_, canonical)| canonical);
    material_library().iter().find(|m| m.name == canonical).cloned()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Diffusivities of the reference table (physical-parameters section 1), rounded there to
    /// two or three significant digits, hence the 5 % tolerance.
    #[test]
    fn diffusivity_matches_reference_table() {
        let reference = [
            ("polystyrene", 1.10e-7),
            ("eps", 1.35e-6),
            ("steel", 1.36e-5),
            ("stainless_steel", 4.0e-6),
            ("glass", 4.8e-7),
            ("brick", 5.2e-7),
            ("aluminium", 6.9e-5),
            ("copper", 1.17e-4),
            ("pmma", 1.1e-7),
            ("pet", 1.2e-7),
            ("pvc", 1.3e-7),
            ("pla", 6.7e-8),
            ("abs", 1.4e-7),
            ("pine", 1.7e-7),
        ];
        assert_eq!(material_library().len(), reference.len());
        for (name, alpha) in reference {
            let m = lookup_material(name).unwrap_or_else(|| panic!("{name} missing"));
            let rel = (m.diffusivity() - alpha).abs() / alpha;
            assert!(rel < 0.05, "{name}: alpha {} vs {alpha}", m.diffusivity());
        }
    }

    #[test]
    fn library_entries_are_valid_and_painted() {
        for m in material_library() {
            m.validate("material").unwrap();
            assert_eq!(m.absorptivity, PAINTED_BLACK, "{}", m.name);
            assert!(m.emissivity >= 0.9, "{}", m.name);
            assert!(m.source.starts_with('['), "{}", m.name);
        }
    }

    #[test]
    fn names_are_case_insensitive_with_aliases() {
        assert_eq!(lookup_material("STEEL").unwrap().name, "steel");
        assert_eq!(lookup_material("Stainless Steel").unwrap().name, "stainless_steel");
        assert_eq!(lookup_material("stainless-steel").unwrap().name, "stainless_steel");
        assert_eq!(lookup_material("aluminum").unwrap().name, "aluminium");
        assert_eq!(lookup_material("Acrylic").unwrap().name, "pmma");
        assert_eq!(lookup_material("soda_lime_glass").unwrap().name, "glass");
        assert_eq!(lookup_material("gpps").unwrap().name, "polystyrene");
        assert!(lookup_material("unobtainium").is_none());
        assert!(lookup_material("").is_none());
    }

    #[test]
    fn overrides_replace_library_values() {
        let spec = MaterialSpec { emissivity: Some(0.07), ..MaterialSpec::named("steel") };
        let m = spec.resolve().unwrap();
        assert_eq!(m.emissivity, 0.07);
        assert_eq!(m.conductivity, 51.9);
        assert!(m.source.contains("overridden in the scene: emissivity"));
    }

    #[test]
    fn explicit_material_needs_all_five() {
        let spec = MaterialSpec {
            density: Some(1000.0),
            specific_heat: Some(1000.0),
            emissivity: Some(0.9),
            absorptivity: Some(0.9),
            ..MaterialSpec::default()
        };
        assert_eq!(
            spec.resolve().unwrap_err().to_string(),
            "material.conductivity: required when material.name is absent"
        );
        let all = MaterialSpec { conductivity: Some(1.0), ..spec };
        let m = all.resolve().unwrap();
        assert_eq!(m.name, "custom");
        assert!((m.diffusivity() - 1e-6).abs() < 1e-18);
        let none = MaterialSpec::default().resolve().unwrap_err().to_string();
        assert!(none.starts_with("material.density: required when material.name is absent"));
        assert!(none.contains("material.absorptivity"), "{none}");
    }

    #[test]
    fn unknown_name_lists_known_names() {
        let err = MaterialSpec::named("stel").resolve().unwrap_err();
        let text = err.to_string();
        assert!(matches!(err, SceneError::UnknownMaterial { .. }));
        assert!(text.starts_with("material.name: unknown material \"stel\""), "{text}");
        assert!(text.contains("steel") && text.contains("pla") && text.contains("aluminum"));
    }
}

//! Method idp's settings: `[simulation.idp]` in a scene file.

/// Method idp's settings: `[simulation.idp]` in a scene file.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IdpSettings {
    /// Resample cells over twice the rest density (`simulation.idp.resample`, or
    /// `simulation.idp_resample` in a file whose method is idp; Kugelstadt et al.'s optional
    /// step, off as in their 3D scene).
    pub resample: bool,
}

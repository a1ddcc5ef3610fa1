//! Method nbflip's settings: `[simulation.nbflip]` in a scene file.

use crate::stages::band::DEFAULT_BAND_R;

/// Method nbflip's settings: `[simulation.nbflip]` in a scene file.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NbflipSettings {
    /// `R`: the band's depth in cells (`simulation.nbflip.band_r`, or `simulation.band_r` in a
    /// file whose method has a band; `--band-r`).
    pub band_r: u32,
    /// Work on the level set only near the surface (`simulation.nbflip.narrow`, default
    /// true); false works on the whole grid every step, with the same results (for measuring
    /// and for tests).
    pub narrow: bool,
}

impl Default for NbflipSettings {
    fn default() -> Self {
        Self {
            band_r: DEFAULT_BAND_R,
            narrow: true,
        }
    }
}

//! The renderer's costs a budget plan times its iterations with, and where they come from: the
//! same reference costs in every front end unless given (issue 42, item 4).

use serde::{Deserialize, Serialize};

use crate::sim::solve::predict::Budget;

/// Seconds per light path, per camera path and pixel, and per iteration, and the pixel count P.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
pub struct Costs {
    /// t_F: seconds per light path (one set serves every pixel).
    pub light_path: f64,
    /// t_B: seconds per camera path and pixel.
    pub camera_path: f64,
    /// t_0: fixed seconds per iteration.
    pub iteration: f64,
    /// P: the pixels of the image the renderer computes.
    pub pixels: f64,
    /// t_M: seconds per merge event and pixel (a kernel evaluation, the weights and the sums):
    /// what makes a larger merge radius cost time (docs/model.md §13). Absent in plans made
    /// before it existed: 0.
    #[serde(default)]
    pub merge: f64,
    /// Where t_F, t_B and t_0 come from.
    #[serde(default)]
    pub source: CostSource,
}

/// Where a plan's costs come from. Every front end — `optimis budget`, `POST /v1/jobs/{id}/budget`,
/// the dashboard's budget card — takes the same [`Costs::REFERENCE`] for a cost not given, so one
/// document and one set of costs give one plan wherever it is asked for (issue 42, item 4);
/// timing this machine is an explicit choice (`optimis budget --measure-costs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum CostSource {
    /// [`Costs::REFERENCE`]: this crate's brute force on the paper's scene, timed once on a 2-core
    /// machine (docs/results.md §7) — a fixed stand-in for a renderer, not this machine.
    #[default]
    Reference,
    /// All three given by the caller (their renderer's).
    Given,
    /// Some given by the caller, the others the reference's.
    Mixed,
    /// Timed on the machine that made the plan, at that moment: differs between machines and runs.
    Measured,
}

impl Costs {
    /// The costs a plan takes when none are given: the brute force on the paper's scene, measured
    /// on a 2-core machine (docs/results.md §7, "Ray budget"), for an image of 10⁶ pixels; the cost
    /// per merge is the restricted engine's time per merge event on the same machine (the slope of
    /// its iteration time against the merges per iteration between R = 0.003 and 0.02,
    /// docs/results.md §22).
    pub const REFERENCE: Costs = Costs {
        light_path: 7.3e-9,
        camera_path: 4.1e-6,
        iteration: 1.9e-4,
        pixels: 1e6,
        merge: 8.0e-8,
        source: CostSource::Reference,
    };

    /// These costs with the given ones put in their place: `t_F`, `t_B`, `t_0` in seconds and P;
    /// the source says whether all, some or none of the three times were given.
    pub fn with_given(
        self,
        light: Option<f64>,
        camera: Option<f64>,
        iteration: Option<f64>,
        pixels: Option<f64>,
    ) -> Costs {
        let given = [light, camera, iteration].iter().filter(|c| c.is_some()).count();
        Costs {
            light_path: light.unwrap_or(self.light_path),
            camera_path: camera.unwrap_or(self.camera_path),
            iteration: iteration.unwrap_or(self.iteration),
            pixels: pixels.unwrap_or(self.pixels),
            merge: self.merge,
            source: match given {
                0 => self.source,
                3 => CostSource::Given,
                _ => CostSource::Mixed,
            },
        }
    }

    /// These costs with the cost per merge `merge` (seconds per merge event and pixel) if given.
    pub fn with_merge(self, merge: Option<f64>) -> Costs {
        Costs { merge: merge.unwrap_or(self.merge), ..self }
    }

    /// Seconds of one renderer iteration at `b`, merges not counted.
    pub fn iteration_seconds(&self, b: Budget) -> f64 {
        self.light_path * b.light_paths as f64 + self.camera_path * b.camera_paths as f64 * self.pixels + self.iteration
    }

    /// Seconds of one renderer iteration at `b` with `merges` merge events per pixel.
    pub fn iteration_seconds_with_merges(&self, b: Budget, merges: f64) -> f64 {
        self.iteration_seconds(b) + self.merge * merges * self.pixels
    }
}

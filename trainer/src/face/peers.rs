//! The peers `cbd compare` runs beside the bases (nominal, DH): one list, [`PEERS`], that the
//! comparison, the commanded tables, the JSON and the HTML report iterate over. A peer is its
//! folder (its fitter: `crate::baselines::<peer>`) plus one entry here; the harnesses
//! (`crate::evaluation::peers::Peer`) never name one.

use crate::baselines::kernel_ridge::{kernel_ridge_correction, SearchOptions};
use crate::calibrate::Settings;
use crate::data::Measurements;
use crate::evaluation::correction::{CorrectionFitter, FittedCorrection};
use crate::evaluation::peers::{Command, Peer};
use cbd_protocol::NominalModel;

/// What the peers' fitters are built from: CbD's settings (from the flags) and kernel ridge's search.
#[derive(Default)]
pub struct PeerContext {
    pub settings: Settings,
    pub search: SearchOptions,
}

/// A peer's correction, built for a context.
pub type Fitter<'c> = Box<dyn Fn(&NominalModel, &Measurements) -> crate::error::Result<FittedCorrection> + 'c>;
/// A peer's blob fit, built for a context.
pub type BlobFit<'c> = Box<dyn Fn(&NominalModel, &Measurements) -> crate::error::Result<Vec<u8>> + 'c>;

/// How the commanded tables command a peer (`evaluation::peers::Command`).
#[derive(Clone, Copy)]
pub enum Commanded {
    /// Pose redefinition through the peer's corrected positions.
    PoseRedefinition,
    /// The blob's own compensation, the blob fitted by this.
    Compensate(for<'c> fn(&'c PeerContext) -> BlobFit<'c>),
    /// No commanded rows.
    No,
}

/// One peer: its rows' names and labels, how it is fitted and commanded.
pub struct PeerEntry {
    /// Its row on the nominal model (and JSON key); `dh+<name>` on the DH-calibrated chain.
    pub name: &'static str,
    /// The HTML report's name of its row.
    pub label: &'static str,
    /// The HTML report's name of its `dh+` row; `None`: fitted on the nominal model only.
    pub dh_label: Option<&'static str>,
    /// Fitted once per tool point (a function of the joints alone), else on the whole chain.
    pub per_tool_point: bool,
    /// Its rows' hyperparameters are listed under the JSON's `"hyperparameters"`.
    pub hyperparameters_in_json: bool,
    pub fitter: for<'c> fn(&'c PeerContext) -> Fitter<'c>,
    pub commanded: Commanded,
}

fn krr_fitter(c: &PeerContext) -> Fitter<'_> {
    Box::new(kernel_ridge_correction(&c.search))
}

fn cbd_fitter(c: &PeerContext) -> Fitter<'_> {
    Box::new(cbd_correction(&c.settings))
}

fn cbd_blob(c: &PeerContext) -> BlobFit<'_> {
    Box::new(move |model: &NominalModel, data: &Measurements| crate::calibrate::calibrate(model, data, &c.settings).map(|c| c.fit.blob))
}

/// Kernel ridge (GP) regression of the residual, its hyperparameters by its own marginal likelihood.
pub const KRR: PeerEntry = PeerEntry {
    name: "krr",
    label: "kernel ridge regression",
    dh_label: Some("DH + kernel ridge"),
    per_tool_point: true,
    hyperparameters_in_json: true,
    fitter: krr_fitter,
    commanded: Commanded::PoseRedefinition,
};

/// Calibration by Diffeomorphisms through the one pipeline, deforming the model it is handed.
pub const CBD: PeerEntry = PeerEntry {
    name: "cbd",
    label: "calibrated (CbD)",
    dh_label: Some("DH + CbD"),
    per_tool_point: false,
    hyperparameters_in_json: false,
    fitter: cbd_fitter,
    commanded: Commanded::Compensate(cbd_blob),
};

/// The peers, in their rows' order (after `nominal` and `dh`).
pub const PEERS: &[PeerEntry] = &[KRR, CBD];

/// A peer's fitters, built for a context.
pub struct Fitters<'c> {
    entry: &'c PeerEntry,
    fit: Fitter<'c>,
    blob: Option<BlobFit<'c>>,
}

impl PeerEntry {
    /// The peer with a fitter of the caller's (tests, other programs) and no commanded rows.
    pub fn with<'a>(&'a self, fit: CorrectionFitter<'a>) -> Peer<'a> {
        self.peer(fit, None)
    }

    fn peer<'a>(&'a self, fit: CorrectionFitter<'a>, command: Option<Command<'a>>) -> Peer<'a> {
        Peer {
            name: self.name,
            on_dh: self.dh_label.is_some(),
            per_tool_point: self.per_tool_point,
            hyperparameters_in_json: self.hyperparameters_in_json,
            fit,
            command,
        }
    }
}

impl Fitters<'_> {
    /// The peer as the harnesses take it.
    pub fn peer(&self) -> Peer<'_> {
        let command = match (self.entry.commanded, &self.blob) {
            (Commanded::PoseRedefinition, _) => Some(Command::PoseRedefinition),
            (Commanded::Compensate(_), Some(blob)) => Some(Command::Compensate(&**blob)),
            _ => None,
        };
        self.entry.peer(&*self.fit, command)
    }
}

/// Every entry's fitters for `context`.
pub fn fitters<'c>(entries: &'c [PeerEntry], context: &'c PeerContext) -> Vec<Fitters<'c>> {
    entries
        .iter()
        .map(|entry| Fitters {
            entry,
            fit: (entry.fitter)(context),
            blob: match entry.commanded {
                Commanded::Compensate(blob) => Some(blob(context)),
                _ => None,
            },
        })
        .collect()
}

/// The HTML report's names of the entries' rows, by key.
pub fn labels(entries: &[PeerEntry]) -> Vec<(String, &'static str)> {
    entries
        .iter()
        .flat_map(|e| std::iter::once((e.name.to_string(), e.label)).chain(e.dh_label.map(|l| (format!("dh+{}", e.name), l))))
        .collect()
}

/// Issue 41's worked change: a new peer is its fitter plus one entry of the list. Here a
/// nominal-only peer — the nominal model shifted by the training rows' mean residual — joins
/// compare's rows, its JSON, the HTML report's labels and the commanded table through
/// `WITH_OFFSET` alone.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::commanded::{commanded_accuracy, fit_and_command, SimulatedArm};
    use crate::evaluation::compare::compare_peers;
    use crate::evaluation::correction::Predictor;

    /// The peer's folder: its fitter.
    fn offset_fitter(_: &PeerContext) -> Fitter<'static> {
        Box::new(|nominal: &NominalModel, data: &Measurements| {
            let m = data.task_dim;
            let predicted = crate::nominal::positions(nominal, &data.joints, m);
            let mut offset = vec![0.0; m];
            for (p, y) in predicted.chunks_exact(m).zip(data.positions.chunks_exact(m)) {
                for c in 0..m {
                    offset[c] += (y[c] - p[c]) / data.len() as f64;
                }
            }
            let (model, shift) = (nominal.clone(), offset.clone());
            let predict: Predictor = Box::new(move |joints: &[f64]| {
                let mut out = crate::nominal::positions(&model, joints, m);
                out.chunks_exact_mut(m).for_each(|p| p.iter_mut().zip(&shift).for_each(|(v, s)| *v += s));
                out
            });
            Ok(FittedCorrection::new(predict, format!("mean residual {offset:?}")))
        })
    }

    const OFFSET: PeerEntry = PeerEntry {
        name: "offset",
        label: "nominal + mean offset",
        dh_label: None,
        per_tool_point: true,
        hyperparameters_in_json: false,
        fitter: offset_fitter,
        commanded: Commanded::PoseRedefinition,
    };

    /// The list with the new peer: its one line.
    const WITH_OFFSET: &[PeerEntry] = &[KRR, CBD, OFFSET];

    #[test]
    fn a_nominal_only_peer_is_one_entry_of_the_list() {
        let real = crate::simulate::rr::RealRr::default();
        let train = real.measure(&crate::simulate::configurations(crate::simulate::Sampling::Grid { per_axis: 8 }, 2));
        let test = real.measure(&crate::simulate::configurations(crate::simulate::Sampling::Uniform { count: 40, seed: 9 }, 2));
        let nominal = crate::simulate::rr::nominal();
        let context = PeerContext { settings: Settings::default(), search: Default::default() };
        let fitters = fitters(WITH_OFFSET, &context);
        let peers: Vec<Peer> = fitters.iter().map(|f| f.peer()).collect();

        let c = compare_peers(&nominal, &train, &test, &peers);
        let names: Vec<&str> = c.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["nominal", "dh", "krr", "dh+krr", "cbd", "dh+cbd", "offset"]);
        let mean = |n: &str| c.rows.iter().find(|r| r.name == n).unwrap().stats.mean;
        assert!(mean("offset") < mean("nominal"), "{}", c.table("m"));
        assert!(c.table("m").lines().any(|l| l.starts_with("offset ")), "{}", c.table("m"));
        let json = c.to_json();
        assert!(json["methods"]["offset"]["mean"].is_number(), "{json}");
        assert_eq!(json["hyperparameters"].as_object().unwrap().keys().collect::<Vec<_>>(), ["dh+krr", "krr"]);
        let page = crate::report::html::render_report(&json, "compare.json", &[], "m", &labels(WITH_OFFSET)).unwrap();
        assert!(page.contains("nominal + mean offset"));

        let arm = SimulatedArm::named("rr").unwrap();
        let commanded = fit_and_command(&arm, &nominal, &train, &peers, commanded_accuracy, 100, 7).unwrap();
        let names: Vec<&str> = commanded.rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["nominal", "dh", "krr", "dh+krr", "cbd", "offset"]);
    }
}

/// CbD through the one calibration pipeline (`crate::calibrate`) on whatever base model the caller
/// gives (nominal, DH-calibrated, with effects), deformed as given (`--geometry nominal`): the blob
/// `cbd fit --geometry nominal` writes for that model, data and flags.
pub fn cbd_correction(
    settings: &crate::calibrate::Settings,
) -> impl Fn(&cbd_protocol::NominalModel, &crate::data::Measurements) -> crate::error::Result<crate::evaluation::correction::FittedCorrection>
{
    let settings = crate::calibrate::Settings { geometry: crate::calibrate::Geometry::Nominal, ..settings.clone() };
    move |nominal: &cbd_protocol::NominalModel,
          data: &crate::data::Measurements|
          -> crate::error::Result<crate::evaluation::correction::FittedCorrection> {
        let calibration = crate::calibrate::calibrate(nominal, data, &settings)?;
        crate::face::print_calibration(&calibration, !settings.solver.verbose);
        let mut note = calibration.describe_hyperparameters();
        if let Some(e) = &calibration.evidence {
            note += &format!("; evidence {:.2} on {} rows ({:.2} s)", e.log_evidence, e.rows_used, e.seconds);
        }
        // Which member of the prior family the row used (docs/DESIGN.md §16).
        let member = if calibration.hyperparameters.configuration.is_some() { "with the configuration field" } else { "CbD's two fields" };
        note += &match &calibration.configuration {
            Some(f) => format!(
                "; prior: {member} (configuration field {} by evidence: {:.1} → {:.1}, margin {:.1})",
                if f.chosen { "chosen" } else { "not chosen" },
                f.plain_log_evidence,
                f.with_term_log_evidence,
                f.margin
            ),
            None => format!("; prior: {member}"),
        };
        note += &format!("; {} ({})", calibration.scheme.label(), calibration.scheme.chosen_by);
        for w in &calibration.warnings {
            note += &format!("; warning: {w}");
        }
        let blob = calibration.fit.blob;
        let predictor: crate::evaluation::correction::Predictor =
            Box::new(move |joints: &[f64]| crate::predict::evaluate_blob(&blob, joints).unwrap_or_else(|_| vec![f64::NAN; joints.len()]));
        Ok(crate::evaluation::correction::FittedCorrection {
            noise_sigma: Some(calibration.hyperparameters.sigma),
            ..crate::evaluation::correction::FittedCorrection::new(predictor, note)
        })
    }
}

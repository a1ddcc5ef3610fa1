//! Writes a [`super::layout`] into the recording as its blueprint.
//!
//! The SDK's blueprint builder (rerun 0.36.3) cannot set view properties (legends, the 3D eye,
//! hidden entities), so the store is written here with the blueprint archetypes, at the paths
//! the viewer reads: `container/<id>`, `view/<id>`, `view/<id>/ViewContents`,
//! `view/<id>/<property archetype>`, `view/<id>/ViewContents/overrides/<entity>/visualizers`.

use super::layout::{Kind, Pane, View};
use rerun::external::re_log_types::external::re_tuid::Tuid;
use rerun::external::re_log_types::{BlueprintActivationCommand, LogMsg, RecordingId};
use rerun::external::re_sdk_types::blueprint::{archetypes as bp, components as bpc};
use rerun::external::re_sdk_types::datatypes::Uuid;
use rerun::{RecordingStream, RecordingStreamBuilder, RecordingStreamResult};

/// Writes `root` as the recording's blueprint, made active and default, its time panel on
/// `timeline`.
pub fn send(rec: &RecordingStream, root: &Pane, timeline: &str) -> RecordingStreamResult<()> {
    let (bp_rec, storage) = RecordingStreamBuilder::new("cellflip")
        .recording_id(RecordingId::random())
        .blueprint()
        .memory()?;
    bp_rec.set_time_sequence("blueprint", 0);
    let root_id = write_pane(&bp_rec, root)?;
    let viewport = bp::ViewportBlueprint::new()
        .with_root_container(bpc::RootContainer(root_id))
        .with_auto_layout(false)
        .with_auto_views(false);
    bp_rec.log("viewport", &viewport)?;
    let collapsed = bp::PanelBlueprint::new().with_state(bpc::PanelState::Collapsed);
    bp_rec.log("blueprint_panel", &collapsed)?;
    bp_rec.log("selection_panel", &collapsed)?;
    let time = bp::TimePanelBlueprint::new()
        .with_state(bpc::PanelState::Collapsed)
        .with_timeline(timeline);
    bp_rec.log("time_panel", &time)?;
    let msgs = storage.take();
    let Some(LogMsg::SetStoreInfo(info)) = msgs.first() else {
        unreachable!("a blueprint stream starts with its store info")
    };
    let cmd = BlueprintActivationCommand {
        blueprint_id: info.info.store_id.clone(),
        make_active: true,
        make_default: true,
    };
    rec.send_blueprint(msgs, cmd);
    Ok(())
}

/// A new blueprint id (a UUID) with its text. Ids must differ between recordings: the viewer
/// keeps a view's state by its id across the recordings it has open, and fails to draw a view
/// whose id another recording gave to a view of another kind.
fn new_id() -> (Uuid, String) {
    let id = Uuid {
        bytes: Tuid::new().as_u128().to_be_bytes(),
    };
    (id, uuid_text(id))
}

/// Logs a pane and everything in it; returns its id.
fn write_pane(rec: &RecordingStream, pane: &Pane) -> RecordingStreamResult<Uuid> {
    let (kind, parts): (bpc::ContainerKind, Vec<(f32, &Pane)>) = match pane {
        Pane::View(v) => return write_view(rec, v),
        Pane::Row(p) => (
            bpc::ContainerKind::Horizontal,
            p.iter().map(|(s, p)| (*s, p)).collect(),
        ),
        Pane::Column(p) => (
            bpc::ContainerKind::Vertical,
            p.iter().map(|(s, p)| (*s, p)).collect(),
        ),
        Pane::Tabs(p) => (
            bpc::ContainerKind::Tabs,
            p.iter().map(|p| (1.0, p)).collect(),
        ),
        Pane::Grid(p) => (
            bpc::ContainerKind::Grid,
            p.iter().map(|p| (1.0, p)).collect(),
        ),
    };
    let mut children = vec![];
    for (_, p) in &parts {
        let id = write_pane(rec, p)?;
        let prefix = if matches!(p, Pane::View(_)) {
            "view"
        } else {
            "container"
        };
        children.push(bpc::IncludedContent::from(format!(
            "{prefix}/{}",
            uuid_text(id)
        )));
    }
    let (id, text) = new_id();
    let shares = parts.iter().map(|(s, _)| *s);
    let mut c = bp::ContainerBlueprint::new(kind).with_contents(children);
    c = match pane {
        Pane::Row(_) => c.with_col_shares(shares.map(bpc::ColumnShare::from)),
        Pane::Column(_) => c.with_row_shares(shares.map(bpc::RowShare::from)),
        _ => c,
    };
    rec.log(format!("container/{text}"), &c)?;
    Ok(id)
}

fn uuid_text(id: Uuid) -> String {
    let hex: String = id.bytes.iter().map(|x| format!("{x:02x}")).collect();
    format!(
        "{}-{}-{}-{}-{}",
        &hex[..8],
        &hex[8..12],
        &hex[12..16],
        &hex[16..20],
        &hex[20..]
    )
}

/// Logs a view, its contents, its properties and its hidden entities.
fn write_view(rec: &RecordingStream, v: &View) -> RecordingStreamResult<Uuid> {
    let (id, text) = new_id();
    let path = format!("view/{text}");
    let contents = bp::ViewContents::new(v.contents.iter().map(|q| q.as_str()));
    rec.log(format!("{path}/ViewContents"), &contents)?;
    let arch = bp::ViewBlueprint::new(class(v.kind))
        .with_display_name(v.name.as_str())
        .with_space_origin(v.origin.as_str());
    rec.log(path.as_str(), &arch)?;
    if v.kind == Kind::TimeSeries {
        let legend = bp::PlotLegend::new()
            .with_visible(v.legend)
            .with_corner(bpc::Corner2D::LeftTop);
        rec.log(format!("{path}/PlotLegend"), &legend)?;
    }
    if v.kind == Kind::TextLog {
        // Debug lines (every shortened time step) only when asked for.
        let levels = [
            rerun::TextLogLevel::CRITICAL,
            rerun::TextLogLevel::ERROR,
            rerun::TextLogLevel::WARN,
            rerun::TextLogLevel::INFO,
        ];
        let rows = bp::TextLogRows::new().with_filter_by_log_level(levels);
        rec.log(format!("{path}/TextLogRows"), &rows)?;
    }
    if let Some(background) = background(v.kind) {
        rec.log(format!("{path}/Background"), &background)?;
    }
    if let Some((position, target)) = v.eye {
        let eye = bp::EyeControls3D::new()
            .with_kind(bpc::Eye3DKind::Orbital)
            .with_position(position)
            .with_look_target(target)
            .with_eye_up([0.0, 1.0, 0.0]);
        rec.log(format!("{path}/EyeControls3D"), &eye)?;
    }
    if let Some([x0, x1, y0, y1]) = v.bounds {
        let range = rerun::external::re_sdk_types::datatypes::Range2D {
            x_range: [x0 as f64, x1 as f64].into(),
            y_range: [y0 as f64, y1 as f64].into(),
        };
        rec.log(
            format!("{path}/VisualBounds2D"),
            &bp::VisualBounds2D::new(range),
        )?;
    }
    for e in &v.hidden {
        let hide = bp::EntityBehavior::new().with_visible(false);
        rec.log(
            format!("{path}/ViewContents/overrides/{e}/visualizers"),
            &hide,
        )?;
    }
    Ok(id)
}

/// The spatial views' background in both of the viewer's themes: the colours of particles,
/// cells and labels are chosen against a dark one (white labels, a speed ramp that ends in
/// white), which the light theme would otherwise turn white (the web viewer follows the
/// browser's theme).
const DARK_BACKGROUND: [u8; 3] = [18, 18, 18];

/// A spatial view's background, dark whatever the viewer's theme.
fn background(kind: Kind) -> Option<bp::Background> {
    match kind {
        Kind::Spatial2D => {
            Some(bp::Background::new(bpc::BackgroundKind::SolidColor).with_color(DARK_BACKGROUND))
        }
        Kind::Spatial3D => Some(bp::Background::new(bpc::BackgroundKind::GradientDark)),
        _ => None,
    }
}

/// The viewer's name of a view kind.
fn class(kind: Kind) -> &'static str {
    match kind {
        Kind::Spatial2D => "2D",
        Kind::Spatial3D => "3D",
        Kind::TimeSeries => "TimeSeries",
        Kind::TextLog => "TextLog",
        Kind::TextDocument => "TextDocument",
    }
}

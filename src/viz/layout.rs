//! The layouts the viewer opens a recording with, written as Rerun's blueprint archetypes.
//!
//! The SDK's Rust blueprint builder sets containers, origins and panels but not a view's own
//! settings (a plot's time axis and legend, a 2D view's bounds, a 3D view's eye and grid); those
//! are what make a recording open on what matters, so the layout is written here, archetype by
//! archetype, as the Python SDK writes it: `container/ID` and `view/ID` entities, each view's
//! settings under `view/ID/NAME`, the root in `viewport`, and the panels.

use super::VizError;
use rerun::blueprint::components as bpc;
use rerun::external::re_sdk_types::blueprint::archetypes as bpa;
use rerun::{AsComponents, SerializedComponentBatch};

/// One view: its class, name, origin, contents and settings.
pub(super) struct View {
    class: &'static str,
    name: String,
    origin: String,
    contents: Vec<String>,
    settings: Vec<(&'static str, Vec<SerializedComponentBatch>)>,
}

impl View {
    fn new(class: &'static str, name: &str, origin: &str) -> Self {
        Self {
            class,
            name: name.to_string(),
            origin: origin.to_string(),
            contents: vec!["$origin/**".to_string()],
            settings: Vec::new(),
        }
    }

    /// A 2D view (images and what is drawn on them, in pixels).
    pub(super) fn spatial_2d(name: &str, origin: &str) -> Self {
        Self::new("2D", name, origin)
    }

    /// A 3D view.
    pub(super) fn spatial_3d(name: &str, origin: &str) -> Self {
        Self::new("3D", name, origin)
    }

    /// A plot of scalars over time.
    pub(super) fn time_series(name: &str, origin: &str) -> Self {
        Self::new("TimeSeries", name, origin)
    }

    /// A markdown document.
    pub(super) fn text_document(name: &str, origin: &str) -> Self {
        Self::new("TextDocument", name, origin)
    }

    /// A list of text log lines.
    pub(super) fn text_log(name: &str, origin: &str) -> Self {
        Self::new("TextLog", name, origin)
    }

    /// The entities shown, as query expressions (`+ /path/**`, `- /path`).
    pub(super) fn with_contents<'a>(mut self, queries: impl IntoIterator<Item = &'a str>) -> Self {
        self.contents = queries.into_iter().map(str::to_string).collect();
        self
    }

    /// A setting of the view itself, stored as the viewer's own UI stores it (`name` is the
    /// archetype's short name, e.g. `VisualBounds2D`).
    pub(super) fn with_setting(mut self, name: &'static str, setting: &dyn AsComponents) -> Self {
        self.settings.push((name, setting.as_serialized_batches()));
        self
    }

    /// A plot over the whole run on `timeline`, its legend in the top-right corner.
    pub(super) fn whole_run(self, timeline: &str) -> Self {
        use rerun::datatypes::{TimeRange, TimeRangeBoundary};
        let whole = TimeRange {
            start: TimeRangeBoundary::Infinite,
            end: TimeRangeBoundary::Infinite,
        };
        let ranges = bpa::VisibleTimeRanges::new([rerun::datatypes::VisibleTimeRange {
            timeline: timeline.into(),
            range: whole,
        }]);
        self.with_setting("VisibleTimeRanges", &ranges)
            .with_setting(
                "TimeAxis",
                &bpa::TimeAxis::new().with_view_range(bpc::TimeRange(whole)),
            )
            .with_setting(
                "PlotLegend",
                &bpa::PlotLegend::new().with_corner(bpc::Corner2D::RightTop),
            )
    }

    /// A plot whose value axis spans `lo` to `hi`.
    pub(super) fn value_range(self, lo: f64, hi: f64) -> Self {
        self.with_setting("ScalarAxis", &bpa::ScalarAxis::new().with_range([lo, hi]))
    }

    /// A 2D view framed on the rectangle from `min` to `max` (pixels).
    pub(super) fn framed(self, min: [f32; 2], max: [f32; 2]) -> Self {
        let bounds = bpa::VisualBounds2D::new(rerun::datatypes::Range2D {
            x_range: [min[0] as f64, max[0] as f64].into(),
            y_range: [min[1] as f64, max[1] as f64].into(),
        });
        self.with_setting("VisualBounds2D", &bounds)
    }

    /// A 3D view seen from `eye` looking at `target` (z up), without the viewer's ground grid.
    pub(super) fn eye(self, eye: [f32; 3], target: [f32; 3]) -> Self {
        self.eye_up(eye, target, [0.0, 0.0, 1.0])
    }

    /// A 3D view seen from `eye` looking at `target`, `up` up, without the viewer's ground grid.
    pub(super) fn eye_up(self, eye: [f32; 3], target: [f32; 3], up: [f32; 3]) -> Self {
        let controls = bpa::EyeControls3D::new()
            .with_kind(bpc::Eye3DKind::Orbital)
            .with_position(eye)
            .with_look_target(target)
            .with_eye_up(up);
        self.with_setting("EyeControls3D", &controls)
            .with_setting("LineGrid3D", &bpa::LineGrid3D::new().with_visible(false))
    }
}

/// A view or a container of them.
pub(super) enum Node {
    /// A view.
    View(View),
    /// Children side by side, in rows, or as tabs, with their shares of the space.
    Container {
        /// Its name (a tab's title), when not the viewer's default.
        name: Option<String>,
        /// How the children are laid out.
        kind: bpc::ContainerKind,
        /// The children.
        children: Vec<Node>,
        /// Their shares of the width (horizontal) or height (vertical); empty: equal.
        shares: Vec<f32>,
    },
}

impl Node {
    /// The container named (its tab's title); a view keeps its own name.
    pub(super) fn named(self, title: &str) -> Self {
        match self {
            Node::Container {
                kind,
                children,
                shares,
                ..
            } => Node::Container {
                name: Some(title.to_string()),
                kind,
                children,
                shares,
            },
            view => view,
        }
    }
}

impl From<View> for Node {
    fn from(v: View) -> Self {
        Node::View(v)
    }
}

/// Children side by side, with their shares of the width.
pub(super) fn row(children: impl IntoIterator<Item = Node>, shares: &[f32]) -> Node {
    container(bpc::ContainerKind::Horizontal, children, shares)
}

/// Children one above the other, with their shares of the height.
pub(super) fn column(children: impl IntoIterator<Item = Node>, shares: &[f32]) -> Node {
    container(bpc::ContainerKind::Vertical, children, shares)
}

/// Children as tabs, the first one open.
pub(super) fn tabs(children: impl IntoIterator<Item = Node>) -> Node {
    container(bpc::ContainerKind::Tabs, children, &[])
}

fn container(
    kind: bpc::ContainerKind,
    children: impl IntoIterator<Item = Node>,
    shares: &[f32],
) -> Node {
    Node::Container {
        name: None,
        kind,
        children: children.into_iter().collect(),
        shares: shares.to_vec(),
    }
}

/// A whole layout: the views and the time panel's timeline and play state.
pub(super) struct Layout {
    /// The root container (or view).
    pub root: Node,
    /// The timeline the time panel shows.
    pub timeline: &'static str,
    /// Whether the viewer plays the recording on opening (paused: at the start; following: at
    /// the end).
    pub play: bpc::PlayState,
}

impl Layout {
    /// Sends the layout as the recording's default and active blueprint.
    pub(super) fn send(&self, rec: &rerun::RecordingStream) -> Result<(), VizError> {
        let application = rec
            .store_info()
            .map(|info| info.application_id().clone())
            .unwrap_or_else(|| "stereotag".into());
        let (bp_rec, storage) = rerun::RecordingStreamBuilder::new(application)
            .blueprint()
            .memory()?;
        // The viewer recognises blueprint data by this timeline.
        bp_rec.set_time_sequence("blueprint", 0);
        let mut ids = Ids::default();
        let mut root = log_node(&bp_rec, &mut ids, &self.root)?;
        if matches!(self.root, Node::View(_)) {
            // A lone view sits in tabs: the viewer wants a container at the root.
            let view = bpc::IncludedContent(format!("view/{}", uuid_text(&root)).as_str().into());
            root = ids.next();
            bp_rec.log(
                format!("container/{}", uuid_text(&root)),
                &bpa::ContainerBlueprint::new(bpc::ContainerKind::Tabs).with_contents([view]),
            )?;
        }
        bp_rec.log(
            "viewport",
            &bpa::ViewportBlueprint::new().with_root_container(bpc::RootContainer(root.into())),
        )?;
        // The blueprint and selection panels collapsed: the views get the whole width (the
        // viewer's own buttons open them again); the time panel collapsed too.
        for panel in ["blueprint_panel", "selection_panel"] {
            bp_rec.log(
                panel,
                &bpa::PanelBlueprint::new().with_state(bpc::PanelState::Collapsed),
            )?;
        }
        let time_panel = bpa::TimePanelBlueprint::new()
            .with_state(bpc::PanelState::Collapsed)
            .with_timeline(self.timeline)
            .with_play_state(self.play);
        bp_rec.log("time_panel", &time_panel)?;
        let msgs = storage.take();
        let Some(id) = msgs.first().map(|m| m.store_id().clone()) else {
            return Ok(());
        };
        rec.send_blueprint(
            msgs,
            rerun::external::re_log_types::BlueprintActivationCommand {
                blueprint_id: id,
                make_active: true,
                make_default: true,
            },
        );
        Ok(())
    }
}

/// Deterministic ids: the layouts are the same on every run, so the viewer's saved changes to
/// one apply to the next.
#[derive(Default)]
struct Ids(u64);

impl Ids {
    fn next(&mut self) -> [u8; 16] {
        self.0 += 1;
        let mut bytes = *b"stereotag-layout";
        bytes[8..].copy_from_slice(&self.0.to_be_bytes());
        // A version-4-shaped UUID, as the viewer's own ids are.
        bytes[6] = (bytes[6] & 0x0f) | 0x40;
        bytes[8] = (bytes[8] & 0x3f) | 0x80;
        bytes
    }
}

/// The UUID's usual text (8-4-4-4-12 hex digits), as the viewer names blueprint entities.
fn uuid_text(b: &[u8; 16]) -> String {
    let hex: String = b.iter().map(|x| format!("{x:02x}")).collect();
    format!(
        "{}-{}-{}-{}-{}",
        &hex[0..8],
        &hex[8..12],
        &hex[12..16],
        &hex[16..20],
        &hex[20..32]
    )
}

/// Logs a node and its children; returns its id.
fn log_node(
    rec: &rerun::RecordingStream,
    ids: &mut Ids,
    node: &Node,
) -> Result<[u8; 16], VizError> {
    let id = ids.next();
    match node {
        Node::View(v) => {
            let path = format!("view/{}", uuid_text(&id));
            rec.log(
                format!("{path}/ViewContents"),
                &bpa::ViewContents::new(
                    v.contents
                        .iter()
                        .map(|q| bpc::QueryExpression(q.as_str().into())),
                ),
            )?;
            rec.log(
                path.as_str(),
                &bpa::ViewBlueprint::new(bpc::ViewClass(v.class.into()))
                    .with_display_name(v.name.as_str())
                    .with_space_origin(v.origin.as_str()),
            )?;
            for (name, batches) in &v.settings {
                rec.log_serialized_batches(
                    format!("{path}/{name}"),
                    false,
                    batches.iter().cloned(),
                )?;
            }
        }
        Node::Container {
            name,
            kind,
            children,
            shares,
        } => {
            let mut paths = Vec::new();
            for child in children {
                let child_id = log_node(rec, ids, child)?;
                let prefix = if matches!(child, Node::View(_)) {
                    "view"
                } else {
                    "container"
                };
                paths.push(bpc::IncludedContent(
                    format!("{prefix}/{}", uuid_text(&child_id)).as_str().into(),
                ));
            }
            let mut arch = bpa::ContainerBlueprint::new(*kind).with_contents(paths);
            if let Some(name) = name {
                arch = arch.with_display_name(name.as_str());
            }
            if !shares.is_empty() {
                arch = match kind {
                    bpc::ContainerKind::Horizontal => arch.with_col_shares(shares.iter().copied()),
                    _ => arch.with_row_shares(shares.iter().copied()),
                };
            }
            rec.log(format!("container/{}", uuid_text(&id)), &arch)?;
        }
    }
    Ok(id)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uuid_text_is_the_usual_hyphenated_form() {
        let mut ids = Ids::default();
        let text = uuid_text(&ids.next());
        assert_eq!(text.len(), 36);
        assert_eq!(text.matches('-').count(), 4);
        assert_ne!(text, uuid_text(&ids.next()));
    }
}

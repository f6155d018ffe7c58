//! Robot descriptions in URDF (wiki.ros.org/urdf/XML): links' inertial
//! tags and the revolute, continuous, prismatic and fixed joints between
//! them, read into a [`Model`] whose links are the robot's moving bodies.
//!
//! A fixed joint's child is merged into its parent (mass, centre of mass and
//! inertia combined about the merged centre of mass), so a model link is a
//! body that moves as one; every URDF link stays reachable as a named
//! [`Frame`] on its body (for contact points and `/tf`). Links are numbered
//! depth first from the root, children in the file's joint order (Pinocchio
//! may order siblings otherwise: match joints by name).
//!
//! The XML is read with `roxmltree` rather than a URDF crate: `urdf-rs`
//! (the maintained one) fills a missing `<inertial>` or `<limit>` with
//! zeros and reports errors without a position, and both must be told
//! apart here, where every error names its line and element. Visual and
//! collision geometry, transmissions and Gazebo tags are not read.
//!
//! Checks, each an error naming the element: a joint type other than
//! revolute, continuous, prismatic or fixed; a `<mimic>` that follows no
//! joint of the robot, a fixed one, or forms a cycle (a mimic joint is a
//! [`Coupling`]: its coordinate follows its leader's, and a fixed joint's
//! `<mimic>` is moot); a zero axis; a
//! revolute or prismatic joint without `<limit>`; duplicate names; a joint
//! whose parent or child is no link; a link with two parents; two roots; a
//! cycle; a negative mass; a moving body (after merging the links fixed to
//! it) whose mass is not positive, whose inertia is not positive
//! semi-definite up to round-off at the body's scale, or that is the last
//! of its branch and has no inertia about its joint. A link welded to a
//! fixed base is not checked: it never moves.

use std::collections::HashMap;

use alnlab_core::bounded;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::model::{Coupling, Joint, Link, Model, Root};
use crate::spatial::parallel_axis;

/// How the robot's root link is held.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Base {
    /// Welded to the world (an arm on its pedestal).
    Fixed,
    /// Free to move and turn (a legged robot, a drone).
    Free,
}

/// A one-DOF joint's limits and dynamics as the URDF states them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointSpec {
    /// Position limits (rad or m); `None` for a continuous joint or when
    /// both are written as 0 (some descriptions' way of saying "unset").
    pub range: Option<(f64, f64)>,
    /// Effort limit (N m or N); `None` when absent or written as 0.
    pub effort: Option<f64>,
    /// Velocity limit (rad/s or m/s), if given and positive.
    pub velocity: Option<f64>,
    /// Viscous damping (N m s/rad or N s/m).
    pub damping: f64,
    /// Coulomb friction (N m or N).
    pub friction: f64,
}

/// A URDF link's frame, placed on the body it moves with.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The URDF link's name.
    pub name: String,
    /// The model link (body) it is part of.
    pub body: usize,
    /// Its pose in the body's frame.
    pub placement: Isometry3<f64>,
}

/// A robot read from URDF.
#[derive(Clone, Debug)]
pub struct Robot {
    /// The `<robot name>`.
    pub name: String,
    /// The link tree: one link per moving body, the root first.
    pub model: Model,
    /// Per model link, the URDF link that heads its body.
    pub links: Vec<String>,
    /// Per model link, the URDF joint that moves it (empty for the root).
    pub joints: Vec<String>,
    /// Per model link, its joint's limits and dynamics (unused for the root).
    pub specs: Vec<JointSpec>,
    /// Every URDF link's frame, in model link order.
    pub frames: Vec<Frame>,
}

impl Robot {
    /// The frame of the URDF link `name`, if there is one.
    pub fn frame(&self, name: &str) -> Option<&Frame> {
        self.frames.iter().find(|f| f.name == name)
    }
}

/// What is wrong with a description, and where.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfError {
    /// Line of the element (1-based; 0 when the document is not XML).
    pub line: u32,
    /// The element, e.g. `<joint name="elbow">`.
    pub element: String,
    /// What is wrong and what was expected.
    pub message: String,
}

impl std::fmt::Display for UrdfError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.element.is_empty() {
            write!(f, "line {}: {}", self.line, self.message)
        } else {
            write!(f, "line {}, {}: {}", self.line, self.element, self.message)
        }
    }
}

type Result<T> = std::result::Result<T, UrdfError>;

/// One `<inertial>`: mass, centre of mass and inertia about it, in the link
/// frame.
#[derive(Clone, Copy, Debug)]
struct Inertial {
    mass: f64,
    com: Vector3<f64>,
    inertia: Matrix3<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
}

struct JointTag<'a> {
    name: &'a str,
    kind: Kind,
    /// The joint it follows, if it mimics one.
    mimic: Option<MimicTag<'a>>,
    parent: &'a str,
    child: &'a str,
    origin: Isometry3<f64>,
    axis: Vector3<f64>,
    spec: JointSpec,
    node: roxmltree::Node<'a, 'a>,
}

/// A `<mimic joint multiplier offset/>`: q = multiplier · q_joint + offset.
struct MimicTag<'a> {
    leader: &'a str,
    multiplier: f64,
    offset: f64,
    node: roxmltree::Node<'a, 'a>,
}

struct LinkTag<'a> {
    name: &'a str,
    inertial: Option<Inertial>,
    node: roxmltree::Node<'a, 'a>,
}

/// The most `<link>` elements a robot may have.
pub const MAX_LINKS: usize = 10_000;

/// Reads a robot from URDF text, with gravity along −z of 9.81 m/s².
pub fn parse(text: &str, base: Base) -> Result<Robot> {
    let doc = roxmltree::Document::parse(text).map_err(|e| UrdfError {
        line: e.pos().row,
        element: String::new(),
        message: format!("not well-formed XML: {e}"),
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "robot" {
        return Err(at(&root, "expected a <robot> element at the top".into()));
    }
    // A xacro file reads as a robot of whatever its macros leave out.
    let xacro = |n: &roxmltree::Node| {
        n.tag_name()
            .namespace()
            .is_some_and(|ns| ns.contains("xacro"))
    };
    if let Some(node) = root.descendants().find(|n| n.is_element() && xacro(n)) {
        return Err(at(
            &node,
            "a xacro element: this is a xacro file, whose links and joints come from macros; \
             expand it to URDF first (`xacro robot.urdf.xacro > robot.urdf`) and give that"
                .into(),
        ));
    }
    let mut links: Vec<LinkTag> = Vec::new();
    let mut joints: Vec<JointTag> = Vec::new();
    for node in root.children().filter(|n| n.is_element()) {
        match node.tag_name().name() {
            "link" => links.push(link_tag(node)?),
            "joint" => joints.push(joint_tag(node)?),
            _ => {}
        }
    }
    if links.len() > MAX_LINKS {
        return Err(at(
            &root,
            format!(
                "has {} links; alnlab takes robots of at most {MAX_LINKS} (the largest of the \
                 example-robot-data collection has a few hundred)",
                links.len()
            ),
        ));
    }
    let link_index = unique(&links, |l| (l.name, l.node), "link")?;
    unique(&joints, |j| (j.name, j.node), "joint")?;
    // Each link's parent joint.
    let mut parent_joint: Vec<Option<usize>> = vec![None; links.len()];
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); links.len()];
    let mut joint_child = Vec::with_capacity(joints.len());
    for (j, joint) in joints.iter().enumerate() {
        let find = |name: &str, role: &str| {
            link_index.get(name).copied().ok_or_else(|| {
                at(
                    &joint.node,
                    format!("its {role} link `{name}` is not a <link> of this robot"),
                )
            })
        };
        let (parent, child) = (find(joint.parent, "parent")?, find(joint.child, "child")?);
        if let Some(other) = parent_joint[child] {
            return Err(at(
                &joint.node,
                format!(
                    "link `{}` already has a parent joint, `{}`; a link hangs from one joint",
                    joint.child, joints[other].name
                ),
            ));
        }
        parent_joint[child] = Some(j);
        children[parent].push(j);
        joint_child.push(child);
    }
    let roots: Vec<usize> = (0..links.len())
        .filter(|&l| parent_joint[l].is_none())
        .collect();
    let root_link = match roots[..] {
        [only] => only,
        [] if links.is_empty() => {
            return Err(at(&root, "expected at least one <link>".into()));
        }
        [] => {
            return Err(at(
                &root,
                "every link has a parent joint, so the joints form a cycle; expected one root link"
                    .into(),
            ));
        }
        [first, second, ..] => {
            return Err(at(
                &links[second].node,
                format!(
                    "a second root: links `{}` and `{}` both have no parent joint; expected one tree",
                    links[first].name, links[second].name
                ),
            ));
        }
    };
    let mut builder = Builder {
        links: &links,
        joints: &joints,
        joint_child: &joint_child,
        children: &children,
        bodies: Vec::new(),
        frames: Vec::new(),
        visited: vec![false; links.len()],
    };
    builder.walk(root_link);
    if let Some(stray) = builder.visited.iter().position(|v| !v) {
        return Err(at(
            &links[stray].node,
            format!(
                "link `{}` cannot be reached from the root `{}`: its joints form a cycle",
                links[stray].name, links[root_link].name
            ),
        ));
    }
    let Builder { bodies, frames, .. } = builder;
    let root_kind = match base {
        Base::Fixed => Root::Fixed,
        Base::Free => Root::Free,
    };
    let mut model_links = Vec::with_capacity(bodies.len());
    for (b, body) in bodies.iter().enumerate() {
        let (mass, c, inertia_com) = body.mass.about_centre();
        let link = Link {
            parent: body.parent,
            joint: body.joint,
            mass,
            c,
            inertia_com,
            l: body.l,
            tip: None,
        };
        // A fixed base's body never moves: its inertia is never used.
        if b > 0 || base == Base::Free {
            let leaf = bodies.iter().all(|other| other.parent != Some(b));
            check_body(&links[body.head], &link, leaf)?;
        }
        model_links.push(link);
    }
    let couplings = couplings(&joints, &bodies)?;
    Ok(Robot {
        name: root.attribute("name").unwrap_or("robot").to_string(),
        model: Model {
            root: root_kind,
            links: model_links,
            gravity: Vector3::new(0.0, 0.0, -9.81),
            couplings,
        },
        links: bodies
            .iter()
            .map(|b| links[b.head].name.to_string())
            .collect(),
        joints: bodies
            .iter()
            .map(|b| b.joint_tag.map_or(String::new(), |j| joints[j].name.into()))
            .collect(),
        specs: bodies.iter().map(|b| b.spec).collect(),
        frames,
    })
}

/// The couplings of the bodies whose joints mimic another, each resolved to
/// a leader that mimics none (a mimic of a mimic composes the two).
fn couplings(joints: &[JointTag], bodies: &[Body]) -> Result<Vec<Coupling>> {
    let body_of = |j: usize| bodies.iter().position(|b| b.joint_tag == Some(j));
    let mut couplings = Vec::new();
    for (follower, body) in bodies.iter().enumerate() {
        let Some(mut j) = body.joint_tag.filter(|&j| joints[j].mimic.is_some()) else {
            continue;
        };
        let (mut multiplier, mut offset) = (1.0, 0.0);
        // A chain of mimics is at most as long as the joints are many.
        for _ in 0..=joints.len() {
            let Some(mimic) = &joints[j].mimic else {
                break;
            };
            let leader = joints
                .iter()
                .position(|t| t.name == mimic.leader)
                .ok_or_else(|| {
                    at(
                        &mimic.node,
                        format!(
                            "follows joint `{}`, which is not a joint of this robot",
                            mimic.leader
                        ),
                    )
                })?;
            if joints[leader].kind == Kind::Fixed {
                return Err(at(
                    &mimic.node,
                    format!(
                        "follows `{}`, a fixed joint; expected a joint that moves",
                        mimic.leader
                    ),
                ));
            }
            (multiplier, offset) = (
                multiplier * mimic.multiplier,
                multiplier * mimic.offset + offset,
            );
            j = leader;
        }
        let leader = match joints[j].mimic {
            Some(_) => None,
            None => body_of(j).filter(|&l| l != follower),
        };
        let Some(leader) = leader else {
            let tag = body.joint_tag.expect("a follower has a joint");
            return Err(at(
                &joints[tag].node,
                "its mimics form a cycle: expected each chain of <mimic> to end at a joint that \
                 follows none"
                    .into(),
            ));
        };
        couplings.push(Coupling {
            follower,
            leader,
            multiplier,
            offset,
        });
    }
    Ok(couplings)
}

/// Reads a robot from a URDF file; errors name the file.
pub fn load(path: &std::path::Path, base: Base) -> std::result::Result<Robot, String> {
    let text = bounded::read_to_string(path, bounded::DESCRIPTION_BYTES, "a robot description")
        .map_err(|e| format!("cannot read robot description {}: {e}", path.display()))?;
    parse(&text, base).map_err(|e| format!("{}: {e}", path.display()))
}

/// Mass and first and second moments about a body's origin, summed over
/// the URDF links merged into it.
#[derive(Clone, Copy, Debug, Default)]
struct MassMoments {
    mass: f64,
    first: Vector3<f64>,
    second: Matrix3<f64>,
}

impl MassMoments {
    /// Adds an inertial placed at `pose` in the body's frame.
    fn add(&mut self, inertial: &Inertial, pose: &Isometry3<f64>) {
        let r = pose.rotation.to_rotation_matrix().into_inner();
        let com = pose * nalgebra::Point3::from(inertial.com);
        let inertia = r * inertial.inertia * r.transpose();
        let m = inertial.mass;
        self.mass += m;
        self.first += com.coords * m;
        self.second += inertia + parallel_axis(&com.coords) * m;
    }

    /// Mass, centre of mass and inertia about it.
    fn about_centre(&self) -> (f64, Vector3<f64>, Matrix3<f64>) {
        if self.mass <= 0.0 {
            return (self.mass, Vector3::zeros(), self.second);
        }
        let c = self.first / self.mass;
        let inertia = self.second - parallel_axis(&c) * self.mass;
        (self.mass, c, (inertia + inertia.transpose()) * 0.5)
    }
}

/// A moving body being assembled from a moving joint's child and the links
/// fixed to it.
struct Body {
    head: usize,
    parent: Option<usize>,
    joint: Joint,
    joint_tag: Option<usize>,
    spec: JointSpec,
    l: Vector3<f64>,
    mass: MassMoments,
}

struct Builder<'t, 'a> {
    links: &'t [LinkTag<'a>],
    joints: &'t [JointTag<'a>],
    /// Per joint, its child link.
    joint_child: &'t [usize],
    /// Per link, the joints it is the parent of.
    children: &'t [Vec<usize>],
    bodies: Vec<Body>,
    frames: Vec<Frame>,
    visited: Vec<bool>,
}

/// A step of the walk from the root: start a body at a link hung from a
/// moving joint, or add a link to a body.
enum Visit {
    Body {
        link: usize,
        parent: Option<usize>,
        joint: Option<usize>,
        placement: Isometry3<f64>,
    },
    Attach {
        link: usize,
        body: usize,
        pose: Isometry3<f64>,
    },
}

impl Builder<'_, '_> {
    /// Walks the tree from `root` depth first, children in document order,
    /// on a stack of its own: a chain of thousands of links needs no call
    /// stack.
    fn walk(&mut self, root: usize) {
        let mut stack = vec![Visit::Body {
            link: root,
            parent: None,
            joint: None,
            placement: Isometry3::identity(),
        }];
        while let Some(visit) = stack.pop() {
            match visit {
                Visit::Body {
                    link,
                    parent,
                    joint,
                    placement,
                } => {
                    let body = self.body(link, parent, joint, &placement);
                    stack.push(Visit::Attach {
                        link,
                        body,
                        pose: Isometry3::identity(),
                    });
                }
                Visit::Attach { link, body, pose } => {
                    self.attach(link, body, &pose);
                    // Reversed, so that the first child is walked first.
                    for &j in self.children[link].iter().rev() {
                        let tag = &self.joints[j];
                        let (pose, child) = (pose * tag.origin, self.joint_child[j]);
                        stack.push(match tag.kind {
                            Kind::Fixed => Visit::Attach {
                                link: child,
                                body,
                                pose,
                            },
                            _ => Visit::Body {
                                link: child,
                                parent: Some(body),
                                joint: Some(j),
                                placement: pose,
                            },
                        });
                    }
                }
            }
        }
    }

    /// Starts a body at `link`, hung from body `parent` by joint `joint`
    /// (whose frame sits at `placement` in the parent body's frame); returns
    /// its index.
    fn body(
        &mut self,
        link: usize,
        parent: Option<usize>,
        joint: Option<usize>,
        placement: &Isometry3<f64>,
    ) -> usize {
        let (kind, spec) = match joint {
            None => (Joint::Ball, no_spec()),
            Some(j) => {
                let tag = &self.joints[j];
                let origin = placement.rotation.to_rotation_matrix().into_inner();
                let joint = match tag.kind {
                    Kind::Prismatic => Joint::Prismatic {
                        origin,
                        axis: tag.axis,
                    },
                    _ => Joint::Revolute {
                        origin,
                        axis: tag.axis,
                    },
                };
                (joint, tag.spec)
            }
        };
        self.bodies.push(Body {
            head: link,
            parent,
            joint: kind,
            joint_tag: joint,
            spec,
            l: placement.translation.vector,
            mass: MassMoments::default(),
        });
        self.bodies.len() - 1
    }

    /// Adds URDF `link` to body `b` at `pose` (body frame). Each link has
    /// one parent joint, so the walk from the root visits a link once;
    /// links it never visits are on a cycle.
    fn attach(&mut self, link: usize, b: usize, pose: &Isometry3<f64>) {
        self.visited[link] = true;
        if let Some(inertial) = &self.links[link].inertial {
            self.bodies[b].mass.add(inertial, pose);
        }
        self.frames.push(Frame {
            name: self.links[link].name.to_string(),
            body: b,
            placement: *pose,
        });
    }
}

fn no_spec() -> JointSpec {
    JointSpec {
        range: None,
        effort: None,
        velocity: None,
        damping: 0.0,
        friction: 0.0,
    }
}

/// Checks a moving body's merged mass, centre of mass and inertia.
/// Checks a moving body (`leaf`: one no other body hangs from).
fn check_body(head: &LinkTag, link: &Link, leaf: bool) -> Result<()> {
    let (mass, c, inertia) = (link.mass, &link.c, &link.inertia_com);
    let body = |what: String| {
        at(
            &head.node,
            format!(
                "the body headed by link `{}` (with the links fixed to it) {what}",
                head.name
            ),
        )
    };
    if !(c.iter().chain(inertia.iter()).all(|x| x.is_finite()) && mass.is_finite()) {
        return Err(body(
            "has a mass, centre of mass or inertia beyond floating point (its numbers are too \
             large); expected a real body's"
                .into(),
        ));
    }
    if mass <= 0.0 {
        // Massless links between hinges (a spherical joint written as
        // three) make a gimbal whose mass matrix is singular where its axes
        // align: human's hips do, within their ranges, and blow up there.
        let why = match leaf {
            true => "",
            false => {
                " (a massless one others hang from makes a gimbal, whose accelerations are \
                 undetermined where its axes align)"
            }
        };
        return Err(body(format!(
            "has mass {mass}; a moving body needs a positive mass in an <inertial>{why}"
        )));
    }
    // Round-off is judged by the body's own scale — its largest inertia,
    // or its mass at its centre's distance from the joint — not by its
    // inertia alone, which may be all round-off (a point mass).
    let scale = inertia.abs().max().max(mass * c.norm_squared());
    let round_off = 1e-12 * scale.max(f64::MIN_POSITIVE);
    let smallest = inertia.symmetric_eigenvalues().min();
    if smallest < -round_off {
        return Err(body(format!(
            "has an inertia about its centre of mass that is not positive semi-definite \
             (smallest eigenvalue {smallest:e}); expected a real body's"
        )));
    }
    // A body others hang from moves their inertia too; a last one that
    // moves none leaves its joint's acceleration undetermined.
    if leaf && link.axis_inertia() <= round_off {
        return Err(body(format!(
            "has no inertia about its joint ({:e}), and no body hangs from it: its mass sits \
             on the axis and its inertia is zero; expected a real body's",
            link.axis_inertia()
        )));
    }
    Ok(())
}

/// The element as an error names it: `<tag name="…">`.
fn describe(node: &roxmltree::Node) -> String {
    match node.attribute("name") {
        Some(name) => format!("<{} name=\"{name}\">", node.tag_name().name()),
        None => format!("<{}>", node.tag_name().name()),
    }
}

fn at(node: &roxmltree::Node, message: String) -> UrdfError {
    UrdfError {
        line: node.document().text_pos_at(node.range().start).row,
        element: describe(node),
        message,
    }
}

/// Checks that names are unique; the index of each by name.
fn unique<'a, T>(
    items: &[T],
    key: impl Fn(&T) -> (&'a str, roxmltree::Node<'a, 'a>),
    what: &str,
) -> Result<HashMap<&'a str, usize>> {
    let mut index = HashMap::new();
    for (i, item) in items.iter().enumerate() {
        let (name, node) = key(item);
        if index.insert(name, i).is_some() {
            return Err(at(
                &node,
                format!("a second {what} named `{name}`; names must be unique"),
            ));
        }
    }
    Ok(index)
}

fn name<'a>(node: roxmltree::Node<'a, 'a>) -> Result<&'a str> {
    match node.attribute("name") {
        Some(n) if !n.is_empty() => Ok(n),
        _ => Err(at(&node, "expected a non-empty `name` attribute".into())),
    }
}

fn child<'a>(node: roxmltree::Node<'a, 'a>, tag: &str) -> Option<roxmltree::Node<'a, 'a>> {
    node.children()
        .find(|n| n.is_element() && n.tag_name().name() == tag)
}

/// A number attribute; `default` when absent.
fn number(node: roxmltree::Node, attribute: &str, default: Option<f64>) -> Result<f64> {
    match node.attribute(attribute) {
        None => default.ok_or_else(|| {
            at(
                &node,
                format!("expected a `{attribute}` attribute (a number)"),
            )
        }),
        Some(text) => match text.trim().parse::<f64>() {
            Ok(x) if x.is_finite() => Ok(x),
            _ => Err(at(
                &node,
                format!("`{attribute}` is `{text}`; expected a finite number"),
            )),
        },
    }
}

/// A three-number attribute (`xyz`, `rpy`); `default` when absent.
fn triple(node: roxmltree::Node, attribute: &str, default: [f64; 3]) -> Result<Vector3<f64>> {
    let Some(text) = node.attribute(attribute) else {
        return Ok(Vector3::from(default));
    };
    let values: Vec<f64> = text
        .split_whitespace()
        .map(|t| t.parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| {
            at(
                &node,
                format!("`{attribute}` is `{text}`; expected three numbers"),
            )
        })?;
    match values[..] {
        [x, y, z] if values.iter().all(|v| v.is_finite()) => Ok(Vector3::new(x, y, z)),
        _ => Err(at(
            &node,
            format!("`{attribute}` is `{text}`; expected three finite numbers"),
        )),
    }
}

/// An `<origin xyz rpy>` (identity when absent). Roll, pitch and yaw are
/// about the fixed x, y and z axes: R = Rz(yaw) Ry(pitch) Rx(roll).
fn origin(node: roxmltree::Node) -> Result<Isometry3<f64>> {
    let Some(o) = child(node, "origin") else {
        return Ok(Isometry3::identity());
    };
    let xyz = triple(o, "xyz", [0.0; 3])?;
    let rpy = triple(o, "rpy", [0.0; 3])?;
    Ok(Isometry3::from_parts(
        Translation3::from(xyz),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_euler_angles(rpy.x, rpy.y, rpy.z)),
    ))
}

fn link_tag<'a>(node: roxmltree::Node<'a, 'a>) -> Result<LinkTag<'a>> {
    let name = name(node)?;
    let inertial = match child(node, "inertial") {
        None => None,
        Some(tag) => {
            let pose = origin(tag)?;
            let mass_tag = child(tag, "mass")
                .ok_or_else(|| at(&node, "its <inertial> has no <mass>".into()))?;
            let mass = number(mass_tag, "value", None)?;
            if mass < 0.0 {
                return Err(at(&node, format!("mass {mass}; expected a mass ≥ 0 (kg)")));
            }
            let i = child(tag, "inertia")
                .ok_or_else(|| at(&node, "its <inertial> has no <inertia>".into()))?;
            let get = |a: &str| number(i, a, None);
            let (xx, xy, xz, yy, yz, zz) = (
                get("ixx")?,
                get("ixy")?,
                get("ixz")?,
                get("iyy")?,
                get("iyz")?,
                get("izz")?,
            );
            let inertia = Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz);
            let r = pose.rotation.to_rotation_matrix().into_inner();
            Some(Inertial {
                mass,
                com: pose.translation.vector,
                // <inertia> is given in the inertial frame; turn it into the
                // link frame.
                inertia: r * inertia * r.transpose(),
            })
        }
    };
    Ok(LinkTag {
        name,
        inertial,
        node,
    })
}

fn joint_tag<'a>(node: roxmltree::Node<'a, 'a>) -> Result<JointTag<'a>> {
    let joint_name = name(node)?;
    let kind = match node.attribute("type") {
        Some("revolute") => Kind::Revolute,
        Some("continuous") => Kind::Continuous,
        Some("prismatic") => Kind::Prismatic,
        Some("fixed") => Kind::Fixed,
        Some(other @ ("floating" | "planar" | "spherical")) => {
            return Err(at(
                &node,
                format!(
                    "joint type `{other}` is not supported; expected revolute, continuous, \
                     prismatic or fixed (a free base is the scene's `base = \"free\"`)"
                ),
            ));
        }
        Some(other) => {
            return Err(at(
                &node,
                format!(
                    "unknown joint type `{other}`; expected revolute, continuous, prismatic or fixed"
                ),
            ));
        }
        None => {
            return Err(at(
                &node,
                "expected a `type` attribute (revolute, continuous, prismatic or fixed)".into(),
            ));
        }
    };
    let mimic = match child(node, "mimic") {
        None => None,
        // A fixed joint moves with nothing (Talos' grippers state one):
        // its <mimic> is moot, as Pinocchio takes it.
        Some(_) if kind == Kind::Fixed => None,
        Some(m) => Some(MimicTag {
            leader: m.attribute("joint").ok_or_else(|| {
                at(
                    &m,
                    "expected a `joint` attribute: the joint it follows".into(),
                )
            })?,
            multiplier: number(m, "multiplier", Some(1.0))?,
            offset: number(m, "offset", Some(0.0))?,
            node: m,
        }),
    };
    let link_of = |tag: &str| -> Result<&'a str> {
        let element =
            child(node, tag).ok_or_else(|| at(&node, format!("expected a <{tag} link=\"…\"/>")))?;
        element
            .attribute("link")
            .ok_or_else(|| at(&element, "expected a `link` attribute".into()))
    };
    let (parent, child_link) = (link_of("parent")?, link_of("child")?);
    let axis = match child(node, "axis") {
        None => Vector3::x(),
        Some(a) => triple(a, "xyz", [1.0, 0.0, 0.0])?,
    };
    let norm = axis.norm();
    if kind != Kind::Fixed && norm <= 1e-9 {
        return Err(at(
            &node,
            format!(
                "its axis is {} {} {}, a zero vector; expected a direction",
                axis.x, axis.y, axis.z
            ),
        ));
    }
    let mut spec = no_spec();
    if let Some(d) = child(node, "dynamics") {
        spec.damping = number(d, "damping", Some(0.0))?;
        spec.friction = number(d, "friction", Some(0.0))?;
        if spec.damping < 0.0 || spec.friction < 0.0 {
            return Err(at(&d, "expected damping and friction ≥ 0".into()));
        }
    }
    match child(node, "limit") {
        None if matches!(kind, Kind::Revolute | Kind::Prismatic) => {
            return Err(at(
                &node,
                "a revolute or prismatic joint needs a <limit lower upper effort velocity/>; \
                 use type=\"continuous\" for an unlimited revolute joint"
                    .into(),
            ));
        }
        None => {}
        Some(limit) => {
            let effort = number(limit, "effort", Some(0.0))?;
            let velocity = number(limit, "velocity", Some(0.0))?;
            if effort < 0.0 || velocity < 0.0 {
                return Err(at(&limit, "expected effort and velocity ≥ 0".into()));
            }
            spec.effort = (effort > 0.0).then_some(effort);
            spec.velocity = (velocity > 0.0).then_some(velocity);
            if matches!(kind, Kind::Revolute | Kind::Prismatic) {
                let lower = number(limit, "lower", Some(0.0))?;
                let upper = number(limit, "upper", Some(0.0))?;
                if upper < lower {
                    return Err(at(
                        &limit,
                        format!("upper {upper} is below lower {lower}; expected lower ≤ upper"),
                    ));
                }
                spec.range = (lower != 0.0 || upper != 0.0).then_some((lower, upper));
            }
        }
    }
    Ok(JointTag {
        name: joint_name,
        kind,
        mimic,
        parent,
        child: child_link,
        origin: origin(node)?,
        axis: if kind == Kind::Fixed {
            axis
        } else {
            axis / norm
        },
        spec,
        node,
    })
}

#[cfg(test)]
mod tests;

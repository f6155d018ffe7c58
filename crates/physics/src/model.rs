//! The articulated body: a tree of rigid links. The root link is free
//! (6 DOF), pinned to the world by a ball hinge (3 DOF) or welded to it (a
//! robot's fixed base); every other link hangs from its parent by a joint:
//! the paper's 3-DOF ball hinge (§2), or a one-degree-of-freedom revolute or
//! prismatic joint of a robot description (§6: "one-degree-of-freedom
//! hinges").

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use crate::spatial::{parallel_axis, rigid_inertia, spatial};

/// How the root link is held.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Root {
    /// Free to move and turn (6 DOF).
    Free,
    /// Turning about a ball hinge fixed in the world (3 DOF).
    Pinned,
    /// Welded to the world at the root position, turned by the root's
    /// (constant) orientation (0 DOF).
    Fixed,
}

/// How a link hangs from its parent. The joint frame is the child link's
/// frame; its origin is the link's proximal hinge.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Joint {
    /// A 3-DOF ball hinge (the paper's): at rest the link's frame is aligned
    /// with its parent's, and the state's quaternion turns it.
    Ball,
    /// Rotation by the joint position q (rad) about a unit `axis` (joint
    /// frame); `origin` is the joint frame's rotation at q = 0 relative to
    /// the parent's frame (columns: the joint frame's axes in parent
    /// coordinates). A URDF revolute or continuous joint.
    Revolute {
        origin: Matrix3<f64>,
        axis: Vector3<f64>,
    },
    /// Translation by the joint position q (m) along a unit `axis` (joint
    /// frame); `origin` as for [`Joint::Revolute`]. A URDF prismatic joint.
    Prismatic {
        origin: Matrix3<f64>,
        axis: Vector3<f64>,
    },
}

impl Joint {
    /// Degrees of freedom.
    pub fn dof(&self) -> usize {
        match self {
            Joint::Ball => 3,
            Joint::Revolute { .. } | Joint::Prismatic { .. } => 1,
        }
    }

    /// The motion subspace of a one-DOF joint (link frame): the spatial
    /// velocity a unit joint velocity gives the child relative to its
    /// parent. `None` for a ball hinge.
    pub fn axis_motion(&self) -> Option<Vector6<f64>> {
        match self {
            Joint::Ball => None,
            Joint::Revolute { axis, .. } => Some(spatial(axis, &Vector3::zeros())),
            Joint::Prismatic { axis, .. } => Some(spatial(&Vector3::zeros(), axis)),
        }
    }
}

/// One rigid link. Its frame has its origin at the proximal hinge.
#[derive(Clone, Debug)]
pub struct Link {
    /// Index of the parent link; `None` for the root.
    pub parent: Option<usize>,
    /// How it hangs from its parent (ignored for the root, which
    /// [`Model::root`] holds).
    pub joint: Joint,
    /// Mass (kg).
    pub mass: f64,
    /// From the proximal hinge to the centre of mass, link frame (m).
    pub c: Vector3<f64>,
    /// Rotational inertia about the centre of mass, link frame (kg m²).
    pub inertia_com: Matrix3<f64>,
    /// From the parent's hinge to this link's hinge (at joint position 0),
    /// parent frame (m). Unused for the root, whose hinge is at the state's
    /// root position.
    pub l: Vector3<f64>,
    /// The distal end point, link frame, if it is a contact point (the free
    /// end of a chain).
    pub tip: Option<Vector3<f64>>,
}

impl Link {
    /// The spatial inertia about the hinge, link frame.
    pub fn spatial_inertia(&self) -> Matrix6<f64> {
        rigid_inertia(self.mass, &self.c, &self.inertia_com)
    }

    /// The link's own inertia about its one-DOF joint's axis through the
    /// hinge (kg m²), or its mass along a prismatic axis (kg): a lower bound
    /// of the inertia the joint moves. For a ball hinge, the smallest
    /// principal inertia about the hinge.
    pub fn axis_inertia(&self) -> f64 {
        match self.joint {
            Joint::Revolute { axis, .. } => axis.dot(&(self.inertia_hinge() * axis)),
            Joint::Prismatic { .. } => self.mass,
            Joint::Ball => self.inertia_hinge().symmetric_eigenvalues().min(),
        }
    }

    /// Rotational inertia about the hinge, link frame (the paper's J).
    pub fn inertia_hinge(&self) -> Matrix3<f64> {
        self.inertia_com + parallel_axis(&self.c) * self.mass
    }
}

/// Shapes whose inertia a link can take.
#[derive(Clone, Copy, Debug)]
pub enum Shape {
    /// A solid box with edges (x, y, z); the hinge at the centre of the −x face.
    Box([f64; 3]),
    /// A rod along x spanning x ∈ [0, `length`] with `radius`; the hinge at
    /// x = 0. Its inertia is that of a solid cylinder of the same size.
    Capsule { length: f64, radius: f64 },
}

impl Shape {
    /// Extent along x (hinge to distal end).
    pub fn length(&self) -> f64 {
        match *self {
            Shape::Box([x, _, _]) => x,
            Shape::Capsule { length, .. } => length,
        }
    }

    /// Rotational inertia about the centre of mass for `mass`, principal axes
    /// along the link frame.
    pub fn inertia_com(&self, mass: f64) -> Matrix3<f64> {
        match *self {
            Shape::Box([x, y, z]) => {
                Matrix3::from_diagonal(&Vector3::new(y * y + z * z, x * x + z * z, x * x + y * y))
                    * (mass / 12.0)
            }
            Shape::Capsule { length, radius } => {
                // Solid cylinder: axial ½ m r², transverse m (3 r² + L²) / 12.
                let axial = 0.5 * mass * radius * radius;
                let transverse = mass * (3.0 * radius * radius + length * length) / 12.0;
                Matrix3::from_diagonal(&Vector3::new(axial, transverse, transverse))
            }
        }
    }
}

/// A one-DOF joint whose coordinate follows another's, as a URDF
/// `<mimic>` states it: q = multiplier · q_leader + offset (so q̇ and q̈
/// follow by the multiplier alone).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coupling {
    /// The following link (its one-DOF joint).
    pub follower: usize,
    /// The link it follows, itself no follower.
    pub leader: usize,
    pub multiplier: f64,
    pub offset: f64,
}

/// A tree of links with gravity.
#[derive(Clone, Debug)]
pub struct Model {
    /// How the root is held.
    pub root: Root,
    /// The links; every parent comes before its children.
    pub links: Vec<Link>,
    /// Gravity, inertial frame (m/s²).
    pub gravity: Vector3<f64>,
    /// The joints that follow others ([`Coupling`]); the dynamics run in
    /// the coordinates that remain, the leaders carrying their followers'
    /// inertia and efforts through the couplings.
    pub couplings: Vec<Coupling>,
}

impl Model {
    /// A chain of `shapes` hinged end to end along each link's x axis, with
    /// the given masses. The last link's distal end is a contact point.
    pub fn chain(root: Root, shapes: &[(Shape, f64)], gravity: Vector3<f64>) -> Model {
        let mut links: Vec<Link> = Vec::with_capacity(shapes.len());
        for (i, (shape, mass)) in shapes.iter().enumerate() {
            let length = shape.length();
            let l = match i {
                0 => Vector3::zeros(),
                _ => Vector3::new(shapes[i - 1].0.length(), 0.0, 0.0),
            };
            links.push(Link {
                parent: i.checked_sub(1),
                joint: Joint::Ball,
                mass: *mass,
                c: Vector3::new(length / 2.0, 0.0, 0.0),
                inertia_com: shape.inertia_com(*mass),
                l,
                tip: (i + 1 == shapes.len()).then(|| Vector3::new(length, 0.0, 0.0)),
            });
        }
        Model {
            root,
            links,
            gravity,
            couplings: Vec::new(),
        }
    }

    /// Number of links.
    pub fn len(&self) -> usize {
        self.links.len()
    }

    /// Whether the model has no links (never, for a valid scene).
    pub fn is_empty(&self) -> bool {
        self.links.is_empty()
    }

    /// Total mass (kg).
    pub fn total_mass(&self) -> f64 {
        self.links.iter().map(|l| l.mass).sum()
    }

    /// Number of degrees of freedom.
    pub fn dof(&self) -> usize {
        let root = match self.root {
            Root::Free => 6,
            Root::Pinned => 3,
            Root::Fixed => 0,
        };
        root + self.links[1..].iter().map(|l| l.joint.dof()).sum::<usize>()
    }

    /// Whether the root's hinge point stays where it is (pinned or welded).
    pub fn root_held(&self) -> bool {
        self.root != Root::Free
    }

    /// The coupling link `i` follows, if it follows one.
    pub fn coupling(&self, i: usize) -> Option<&Coupling> {
        self.couplings.iter().find(|c| c.follower == i)
    }

    /// Sets every follower's position and velocity from its leader's, as
    /// its coupling says.
    pub fn impose_couplings(&self, state: &mut crate::dynamics::State) {
        for c in &self.couplings {
            state.q[c.follower] = c.multiplier * state.q[c.leader] + c.offset;
            state.qd[c.follower] = c.multiplier * state.qd[c.leader];
        }
    }
}

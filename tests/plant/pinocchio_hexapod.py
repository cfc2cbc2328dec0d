"""The 6-UPS hexapod in Pinocchio: a second multibody engine, a truth for tests (not product code).

Built from StewartParams' tables alone (joint positions, masses, inertias, gravity): no kinematics
or dynamics of the kit is called, and the RPY maps are Pinocchio's own (``pin.rpy``).

Model. A kinematic tree closed by constraints, solved by Pinocchio's constrained dynamics
(``pin.constraintDynamics``: the KKT system's Cholesky with proximal iterations):

* the platform: a free-flyer joint whose parent is the base, so its configuration is {P} in {B};
* each leg: a universal joint at B_i (the cylinder: mass m_f at l_f along the leg, inertia
  diag(I_t, I_t, I_axial) about its centre), then a prismatic joint along the leg whose
  coordinate is the leg length (the rod: m_m at l_m back from a_i); the actuator force is the
  prismatic joint's force;
* the S joints: six 3D point constraints (CONTACT_3D) between each rod's end and a_i on the
  platform; a point constraint carries no torque, as a spherical joint.

Why constraints and not a reduced model: the loop closures are then Pinocchio's to solve, so no
leg kinematics of ours (lengths, rates, the Jacobian) enters the accelerations; the closed tree
has 24 coordinates, 18 constraints and 6 degrees of freedom.

The U joint. The kit's legs do not spin about their axis relative to the base: their relative
angular velocity is s × ṡ (docs/conventions/stewart-6ups.md). A universal joint gives that only
where its first axis is perpendicular to the leg: its spin rate is q1' sin q2. No holonomic joint
holds "no spin" over a motion, so at each state the U joints' placements are set with their local
z along the leg and both angles 0: the joint's two axes are then both perpendicular to the leg,
its spin rate and the spin's contribution to the dynamics (the axial moment goes to the joint's
reaction, as in the kit) are the kit's at that instant, which is all that a state's dynamics sees.

The moving base. The base is then Pinocchio's root: a free-flyer under the universe, its
configuration and velocity the base's, its acceleration prescribed by a 6D constraint to the
universe (CONTACT_6D) whose desired acceleration is the base's body acceleration. Gravity is the
model's gravity, along -z of {W}. With a fixed base the tree hangs from the universe directly.

Inverse dynamics: the platform's acceleration is affine in the leg forces, so seven constrained
forward-dynamics solves (no force, then each leg's force alone) give it, and a 6x6 solve gives the forces.
"""
import numpy as np

try:
    import pinocchio as pin
except ImportError:   # the tests skip; pin comes with the dev extra
    pin = None

E_Z = np.array([0.0, 0.0, 1.0])


def _frame_along(s):
    """A rotation whose z axis is the unit vector s (x, y: any perpendicular pair)."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(s[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, s)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(s, x), s])


def _rpy_kinematics(rpy, rate, acc=None):
    """Rotation, angular velocity and (given ``acc``) angular acceleration, in the parent frame."""
    R = pin.rpy.rpyToMatrix(*rpy)
    E = pin.rpy.computeRpyJacobian(rpy, pin.WORLD)
    omega = E @ rate
    if acc is None:
        return R, omega, E
    return R, omega, E @ acc + pin.rpy.computeRpyJacobianTimeDerivative(rpy, rate, pin.WORLD) @ rate


def _free_flyer_state(pose, rate, acc=None):
    """Free-flyer q, body velocity and (given ``acc``) body acceleration of a pose [x, y, z, rpy]
    with its time derivatives."""
    R, omega, *rest = _rpy_kinematics(pose[3:], rate[3:], None if acc is None else acc[3:])
    q = np.concatenate([pose[:3], pin.Quaternion(R).coeffs()])
    v = np.concatenate([R.T @ rate[:3], R.T @ omega])
    if acc is None:
        return q, v
    return q, v, np.concatenate([R.T @ (acc[:3] - np.cross(omega, rate[:3])), R.T @ rest[0]])


class PinocchioHexapod:
    """The hexapod of ``params`` (StewartParams) as a constrained Pinocchio model, fixed base or
    moving base (``moving_base``): ``forward_dynamics`` and ``inverse_dynamics`` take the kit's
    arguments (single states) and return its quantities."""

    def __init__(self, params, moving_base=False, accuracy=1e-13):
        self.params, self.moving_base = params, moving_base
        model = pin.Model()
        model.gravity = pin.Motion(np.array([0.0, 0.0, -params.gravity]), np.zeros(3))
        base = 0
        if moving_base:
            base = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
        self.platform = model.addJoint(base, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "platform")
        model.appendBodyToJoint(self.platform, pin.Inertia(params.platform_mass, params.platform_com,
                                                            np.diag(params.platform_inertia)), pin.SE3.Identity())
        self.u_joints, self.prismatic = [], []
        for i, joint in enumerate(params.base_joints):
            u = model.addJoint(base, pin.JointModelUniversal(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])),
                               pin.SE3(np.eye(3), joint), f"u{i + 1}")
            model.appendBodyToJoint(u, self._leg_inertia(params.cylinder_mass, params.cylinder_com,
                                                         params.cylinder_inertia), pin.SE3.Identity())
            p = model.addJoint(u, pin.JointModelPZ(), pin.SE3.Identity(), f"leg{i + 1}")
            model.appendBodyToJoint(p, self._leg_inertia(params.rod_mass, -params.rod_com, params.rod_inertia),
                                    pin.SE3.Identity())
            self.u_joints.append(u)
            self.prismatic.append(p)
        self.model, self.data = model, model.createData()
        self.constraints = pin.StdVec_RigidConstraintModel()
        for p, a in zip(self.prismatic, params.platform_joints):
            self.constraints.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, p, pin.SE3.Identity(),
                                                             self.platform, pin.SE3(np.eye(3), a), pin.LOCAL))
        if moving_base:
            self.constraints.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_6D, model, base,
                                                             pin.SE3.Identity(), 0, pin.SE3.Identity(), pin.LOCAL))
        self.constraint_data = pin.StdVec_RigidConstraintData()
        for c in self.constraints:
            self.constraint_data.append(c.createData())
        pin.initConstraintDynamics(model, self.data, self.constraints, self.constraint_data)
        self.settings = pin.ProximalSettings(accuracy, 0.0, 10)
        self.v_platform = model.joints[self.platform].idx_v
        self.v_prismatic = [model.joints[p].idx_v for p in self.prismatic]

    @staticmethod
    def _leg_inertia(mass, com, inertia):
        """A leg part's inertia in its joint frame (z along the leg): centre ``com`` along z,
        ``inertia`` = (axial, transverse, transverse) about the centre."""
        return pin.Inertia(mass, com * E_Z, np.diag([inertia[1], inertia[2], inertia[0]]))

    def state(self, pose, pose_rate, base_pose=None, base_rate=None):
        """(q, v) of the tree at a state of the platform (its pose in {B} and its RPY rates), the
        U joints placed along the legs with zero angles (module docstring)."""
        model, params = self.model, self.params
        q, v = np.zeros(model.nq), np.zeros(model.nv)
        if self.moving_base:
            jb = model.joints[1]
            q[jb.idx_q:jb.idx_q + 7], v[jb.idx_v:jb.idx_v + 6] = _free_flyer_state(base_pose, base_rate)
        jp = model.joints[self.platform]
        qp, vp = _free_flyer_state(pose, pose_rate)
        q[jp.idx_q:jp.idx_q + 7], v[jp.idx_v:jp.idx_v + 6] = qp, vp
        R, omega, _ = _rpy_kinematics(pose[3:], pose_rate[3:])
        for u, p, B, a in zip(self.u_joints, self.prismatic, params.base_joints, params.platform_joints):
            leg = pose[:3] + R @ a - B
            length = np.linalg.norm(leg)
            s = leg / length
            leg_rate = pose_rate[:3] + np.cross(omega, R @ a)
            length_rate = s @ leg_rate
            frame = _frame_along(s)
            model.jointPlacements[u] = pin.SE3(frame, B)
            relative = np.cross(s, (leg_rate - length_rate * s) / length)   # the leg's s x ds/dt
            ju, jpr = model.joints[u], model.joints[p]
            v[ju.idx_v:ju.idx_v + 2] = (frame.T @ relative)[:2]
            q[jpr.idx_q], v[jpr.idx_v] = length, length_rate
        return q, v

    def _base_acceleration(self, base_pose, base_rate, base_acc):
        if self.moving_base:
            self.constraint_data[-1].contact_acceleration_desired = pin.Motion(
                _free_flyer_state(base_pose, base_rate, base_acc)[2])

    def _solve(self, q, v, forces):
        tau = np.zeros(self.model.nv)
        tau[self.v_prismatic] = forces
        return pin.constraintDynamics(self.model, self.data, q, v, tau, self.constraints, self.constraint_data,
                                      self.settings)

    def _pose_acc(self, ddq, pose, pose_rate):
        """The platform's RPY pose accelerations from its free-flyer acceleration."""
        R, omega, E = _rpy_kinematics(pose[3:], pose_rate[3:])
        a = ddq[self.v_platform:self.v_platform + 6]
        omega_dot = R @ a[3:]
        rpy_acc = np.linalg.solve(E, omega_dot - pin.rpy.computeRpyJacobianTimeDerivative(
            pose[3:], pose_rate[3:], pin.WORLD) @ pose_rate[3:])
        return np.concatenate([R @ a[:3] + np.cross(omega, pose_rate[:3]), rpy_acc])

    def forward_dynamics(self, pose, pose_rate, forces, base_pose=None, base_rate=None, base_acc=None):
        """Pose accelerations (6,) under leg forces (6,), as plant.hexapod.model.forward_dynamics."""
        q, v = self.state(pose, pose_rate, base_pose, base_rate)
        self._base_acceleration(base_pose, base_rate, base_acc)
        return self._pose_acc(self._solve(q, v, forces), pose, pose_rate)

    def inverse_dynamics(self, pose, pose_rate, pose_acc, base_pose=None, base_rate=None, base_acc=None):
        """Leg forces (6,) that give ``pose_acc``, from seven constrained forward solves."""
        q, v = self.state(pose, pose_rate, base_pose, base_rate)
        self._base_acceleration(base_pose, base_rate, base_acc)
        free = self._pose_acc(self._solve(q, v, np.zeros(6)), pose, pose_rate)
        probe = 1e4   # [N]: of the forces' size, so the differences lose no digits to the free motion
        gain = np.column_stack([self._pose_acc(self._solve(q, v, unit), pose, pose_rate) - free
                                for unit in probe * np.eye(6)]) / probe
        return np.linalg.solve(gain, pose_acc - free)

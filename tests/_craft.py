"""A shared 3-DOF design model (20) for tests: INFANTE-class magnitudes (see
``vcjax.vehicles.infante.describe``), rounded; and the rudder's sway force per yaw moment."""

from vcjax.vehicles import design3dof as d3

CRAFT = d3.design3dof(
    m11=3687.0,
    m22=5900.0,
    m23=-252.0,
    m33=9211.0,
    d11=400.0,
    d22=1000.0,
    d23=-1400.0,
    d32=345.0,
    d33=3360.0,
)
#: sway force per unit yaw moment of a stern rudder [1/m] (INFANTE-class: Y_delta / N_delta)
K_RUDDER = -0.46

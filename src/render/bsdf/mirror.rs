//! The ideal mirror: a Dirac delta lobe, f(ωi, ωo) = ρs δ(ωi − R(ωo)) / cos θi, so that the
//! reflected radiance is ρs L(R(ωo)). In the local frame R(ω) = (−x, −y, z).

use crate::math::Vec3;

#[inline]
pub fn reflect_local(wo: Vec3) -> Vec3 {
    Vec3::new(-wo.x, -wo.y, wo.z)
}

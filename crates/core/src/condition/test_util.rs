//! What the condition modules' tests share.

use super::parts::Parts;
use crate::gearbox::Gearbox;

/// The PHM 2009 spur train's kinematics: 32T → 96T, 48T → 80T (shafts `in`, `idler` at 1/3,
/// `out` at 1/5), nothing else described.
pub fn spur_train() -> Gearbox {
    Gearbox::parse(
        "format = \"gearwear-gearbox\"\nversion = 1\nname = \"s\"\ninput_shaft = \"in\"\n\
         [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"in\", teeth = 32 }\n\
         gear = { shaft = \"idler\", teeth = 96 }\n\
         [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"idler\", teeth = 48 }\n\
         gear = { shaft = \"out\", teeth = 80 }\n",
        "test",
    )
    .expect("the spur train parses")
}

/// [`spur_train`]'s parts.
pub fn spur() -> Parts {
    Parts::of(&spur_train())
}

//! The Embree diff as a test: strahl and Embree trace the same rays on the project's own scenes
//! (and the shared bunny and Sponza when present) and must agree on hit/miss for at least 99.99%
//! of the rays of every class. Timing is not asserted here; the harness measures it.

use std::path::Path;

use compare::harness::{self, Settings};
use compare::{embree, scenes};

fn check(spec: &scenes::SceneSpec, width: u32) {
    let pool = compare::pool(2).unwrap();
    let device = embree::Device::new("threads=2").unwrap();
    let settings = Settings { width, passes: 0, build_repeats: 1, ..Settings::default() };
    let r = harness::run_scene(spec, &pool, &device, &settings, |_| {}).unwrap();
    assert_eq!(r.classes.len(), 3);
    for c in &r.classes {
        let a = &c.accuracy;
        let what = format!("{} {}", r.name, c.class.name());
        assert!(c.rays > 0, "{what}: no rays");
        assert!(a.hit_miss_agreement >= 0.9999, "{what}: hit/miss agreement {}", a.hit_miss_agreement);
        assert!(a.prim_agreement >= 0.999, "{what}: primitive agreement {}", a.prim_agreement);
        assert!(a.t_rel_max < 1e-4, "{what}: t differs by {} relative", a.t_rel_max);
        assert_eq!(a.classified.strahl_error, 0, "{what}: strahl errors {:?}", a.worst);
        assert!(c.strahl_apis_consistent >= 0.9999, "{what}: strahl APIs disagree");
    }
    // The scene is in view: a fair share of primary rays hit.
    assert!(r.classes[0].hit_rate > 0.1, "{}: primary hit rate {}", r.name, r.classes[0].hit_rate);
}

#[test]
fn data_scenes_agree_with_embree() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data");
    for spec in scenes::data(&data) {
        check(&spec, 256);
    }
}

#[test]
fn shared_scenes_agree_with_embree_when_present() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes");
    for spec in scenes::shared(&root).into_iter().filter(|s| s.name == "bunny" || s.name == "sponza_dabrovic") {
        check(&spec, 128);
    }
}

//! `compare --solids` as a test: every solid family traced by strahl and by Embree (user
//! geometry running strahl's own solid test, in both of Embree's layouts) gives the same answer
//! on every primary, shadow and diffuse ray. Timing is not asserted here; the harness measures it.

#[test]
fn both_engines_agree_on_every_solid_family_in_both_layouts() {
    let pool = compare::pool(2).unwrap();
    let out = std::env::temp_dir().join(format!("strahl_solids_agree_{}", std::process::id()));
    for one_geometry in [false, true] {
        let r = compare::solids::run(24, 0, &[], one_geometry, &pool, &out).unwrap();
        assert_eq!(r.families.len(), 10);
        for f in &r.families {
            assert_eq!(f.solids, 512);
            for c in &f.classes {
                let what = format!("{} {} (one geometry: {one_geometry})", f.family, c.class);
                assert!(c.rays > 100, "{what}: {} rays", c.rays);
                assert!(c.hit_rate > 0.1 && c.hit_rate < 0.95, "{what}: hit rate {}", c.hit_rate);
                assert_eq!((c.hit_miss_differ, c.key_differ, c.t_differ), (0, 0, 0), "{what}");
            }
        }
    }
    let unknown = compare::solids::run(24, 0, &["no such family".to_string()], false, &pool, &out);
    assert!(unknown.unwrap_err().to_string().contains("the families are"));
    std::fs::remove_dir_all(&out).ok();
}

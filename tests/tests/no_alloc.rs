//! The 1 kHz path allocates nothing (DESIGN section 6): a counting global allocator over the
//! default scenario's whole servo run in one thread, the plant's tick ([`PlantTick::outputs`] +
//! [`PlantTick::advance`]) and the controller's step ([`Controller::process`]) counted apart,
//! after a warm-up; and the same with the recorder hand-off of every tick and event. This file
//! is its own test binary, so the counting allocator is the global one of nothing else.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use controller::Controller;
use messages::state_flags;
use plant_sim::contact::StripDetail;
use plant_sim::physics::Physics;
use plant_sim::recording::TimingRecord;
use plant_sim::run::{open_recorder, RecordingAbout};
use plant_sim::PlantTick;
use scenarios::{Mode, Scenario};

struct Counting;

thread_local! {
    /// Allocations made by this thread only, so the test harness's own threads cannot interfere.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

fn count() {
    ALLOCATIONS.with(|n| n.set(n.get() + 1));
}

// SAFETY: every method forwards to System, which upholds the GlobalAlloc contract.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Ticks before counting starts: the first connection's event text, lazily initialised statics.
const WARM_UP_TICKS: u64 = 50;

#[test]
fn plant_tick_and_controller_step_do_not_allocate_over_a_whole_servo_run() {
    servo_run_allocates_nothing("default.toml", None);
}

/// The windowed long strip (issue 25): the chain's pool of windows is allocated at start; its
/// first 4 s (contact, the force ramp, the first 80 mm of rolling: eight window hand-overs and
/// slot reuses) allocate nothing.
#[test]
fn the_windowed_long_strip_does_not_allocate_in_the_loop() {
    servo_run_allocates_nothing("long_seal.toml", Some(4000));
}

/// A contour (issue 26): the plant's projection on the contour and the controller's moving frame
/// and time law, through the approach, the first line, the first corner and into the second line.
#[test]
fn a_contour_run_does_not_allocate_in_the_loop() {
    servo_run_allocates_nothing("sunroof.toml", Some(6000));
}

/// Counts the plant's and the controller's allocations over a lockstep servo run of the shipped
/// scenario `name` (its first `ticks`, else the whole run).
fn servo_run_allocates_nothing(name: &str, ticks: Option<u64>) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios").join(name);
    let s = Scenario::load(&path).unwrap();
    let mut plant = PlantTick::from_scenario(&s, &strip::cache::cache_dir(), Mode::Lockstep).unwrap();
    let mut controller = Controller::from_scenario(&s).with_id(1);
    let n_ticks = ticks.unwrap_or_else(|| plant_sim::run::run_length(&s, None).unwrap().n_ticks);
    let (mut plant_allocations, mut controller_allocations) = (0, 0);
    let (mut counted, mut in_contact) = (0, 0);
    while plant.tick() < n_ticks {
        let a0 = allocations();
        let (state, wrench) = plant.outputs();
        let a1 = allocations();
        let (torque, diag) = controller.process(&state, &wrench);
        let a2 = allocations();
        let outcome = plant.advance(Some(&torque));
        let a3 = allocations();
        std::hint::black_box((&diag, &outcome));
        if state.tick >= WARM_UP_TICKS {
            plant_allocations += (a1 - a0) + (a3 - a2);
            controller_allocations += a2 - a1;
            counted += 1;
            in_contact += u64::from(state.flags & state_flags::IN_CONTACT != 0);
        }
    }
    // The counted ticks are the run: approach, contact, roll over the bulge, lift-off.
    assert!(counted >= 2000, "{counted} ticks counted");
    assert!(in_contact >= 1000 && in_contact < counted + u64::from(ticks.is_some()), "{in_contact} of {counted} counted ticks in contact");
    assert_eq!(plant.first_ticks().safe_stop, None, "the servo run as the scenario describes it");
    // The counter works: a Vec does allocate.
    let probe = allocations();
    std::hint::black_box(vec![1u8; 16]);
    assert_eq!(allocations(), probe + 1);
    assert_eq!(plant_allocations, 0, "{plant_allocations} heap allocations in PlantTick::outputs/advance over {counted} ticks");
    assert_eq!(controller_allocations, 0, "{controller_allocations} heap allocations in Controller::process over {counted} ticks");
}

/// A stalled controller mid-roll: the misses, the safe stop's position hold (computed torque with
/// the plant's mass matrix), the controller's return and its blend from the hold allocate nothing.
#[test]
fn a_stall_s_safe_stop_hold_and_take_over_do_not_allocate() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let s = Scenario::load(&path).unwrap();
    let mut plant = PlantTick::from_scenario(&s, &strip::cache::cache_dir(), Mode::Lockstep).unwrap();
    let mut controller = Controller::from_scenario(&s).with_id(1);
    let mut step = |plant: &mut PlantTick, answer: bool| {
        let a0 = allocations();
        let (state, wrench) = plant.outputs();
        let torque = answer.then(|| controller.process(&state, &wrench).0);
        let a1 = allocations();
        let outcome = plant.advance(torque.as_ref());
        std::hint::black_box(&outcome);
        (allocations() - a1, state.flags & state_flags::IN_CONTACT != 0, a1 - a0)
    };
    // Into the roll, pressing (and the first of everything: events' texts, lazy statics).
    while plant.tick() < 2000 {
        step(&mut plant, true);
    }
    let (mut plant_allocations, mut in_contact) = (0, 0);
    for k in 0..700 {
        // 500 ticks without an answer (20 misses, then the hold), then 200 answered (the blend).
        let (a, contact, _) = step(&mut plant, k >= 500);
        plant_allocations += a;
        in_contact += u32::from(contact);
    }
    assert!(plant.first_ticks().safe_stop.is_some_and(|t| t >= 2000), "the stall safe-stopped");
    assert_eq!(plant.gate().status(), messages::PlantStatus::Running, "and the controller came back");
    assert!(plant.gate().hold_anchor().is_some(), "the stop was a position hold");
    assert!(in_contact >= 650, "pressing through the hold: {in_contact} of 700 ticks in contact");
    assert_eq!(plant_allocations, 0, "{plant_allocations} heap allocations in PlantTick::outputs/advance over the stall");
}

#[test]
fn handing_every_tick_to_the_recorder_does_not_allocate() {
    // The record with its centre line, and the record that leaves it to the writer thread
    // (the daemons' default: `StripDetail::Modal`), whose expansion runs there.
    for detail in [StripDetail::Full, StripDetail::Modal] {
        let (allocated, counted) = recorder_hand_off_allocations(detail);
        assert_eq!(allocated, 0, "{detail:?}: {allocated} heap allocations in the tick plus recorder hand-off over {counted} ticks");
    }
}

fn recorder_hand_off_allocations(detail: StripDetail) -> (usize, usize) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/default.toml");
    let s = Scenario::load(&path).unwrap();
    let physics = Physics::new(&s, &strip::cache::cache_dir()).unwrap();
    let dir = harness::temp_dir(&harness::unique_rig("no-alloc"));
    let about =
        RecordingAbout { rig: "no-alloc", mode: Mode::Lockstep, scenario_path: &path, scenario_text: String::new(), transport: None };
    let mut recorder = open_recorder(&dir.join("run.mcap"), &about, &s, &physics, None).unwrap();
    assert!(recorder.expands_centre_line(), "the default strip's centre line can be left to the writer");
    let mut plant = PlantTick::new(&s, physics, Mode::Lockstep).with_strip_detail(detail).with_top_line_every(recorder.scene_every());
    let mut controller = Controller::from_scenario(&s).with_id(1);
    let n_ticks = 2500;
    let mut hand_on = plant_sim::tick_events::EventHandOn::new(plant.period_ns());
    let (mut allocated, mut counted) = (0, 0);
    while plant.tick() < n_ticks {
        let a0 = allocations();
        let (state, wrench) = plant.outputs();
        let (torque, diag) = controller.process(&state, &wrench);
        plant_sim::tick_events::make_room_for_tick(Some(&mut recorder));
        let outcome = plant.advance(Some(&torque));
        hand_on.hand_on(&outcome.events, Some(&mut recorder));
        let timing = TimingRecord { missed: outcome.decision.missed, ..TimingRecord::default() };
        recorder.record_tick_commanded(&plant_sim::tick::tick_record(state, wrench, &outcome, Some(diag), timing), Some(&torque));
        if state.tick >= WARM_UP_TICKS {
            allocated += allocations() - a0;
            counted += 1;
        }
    }
    let dropped = recorder.dropped();
    recorder.finish().unwrap();
    assert_eq!(dropped, 0, "{detail:?}: the writer kept up, so every tick went through the queue");
    (allocated, counted)
}

/// The EGM driver's run (`[egm] enabled`, lockstep) against the real `egm-controller` over UDP:
/// the plant's tick core, the servo, the `EgmRobot` encoding and the sensor messages' decoding.
/// Its allocations do not grow with the run's length: a run of 2400 ticks makes exactly as many
/// as one of 400 (the set-up's), so the ticks between make none. Build first:
/// `cargo build --release --workspace --bins`.
#[test]
fn the_egm_driver_does_not_allocate_per_tick() {
    let counts: Vec<(u64, usize)> = [400u64, 2400].iter().map(|&n| (n, egm_run_allocations(n))).collect();
    eprintln!("EGM driver allocations (ticks, allocations): {counts:?}");
    assert_eq!(counts[0].1, counts[1].1, "the EGM driver allocated per tick: {counts:?}");
}

/// Allocations of this thread over one lockstep EGM run of `n_ticks` (set-up included).
fn egm_run_allocations(n_ticks: u64) -> usize {
    use harness::{bin, egm_scenario_on, free_port, temp_dir, unique_rig, wait_bound, Daemon};
    let dir = temp_dir(&unique_rig("no-alloc-egm"));
    let port = free_port();
    let sc = egm_scenario_on(&dir, port);
    let s = Scenario::load(&sc).unwrap();
    let mut sensor = Daemon::start("egm-controller", &bin("egm-controller"), &["--scenario", sc.to_str().unwrap()], &dir);
    wait_bound(port, &mut sensor);
    let mut plant = PlantTick::from_scenario(&s, &strip::cache::cache_dir(), Mode::Lockstep).unwrap();
    let params = plant_sim::driver::egm::EgmParams::from_scenario(&s, Mode::Lockstep, n_ticks).unwrap();
    let a0 = allocations();
    let mut egm = plant_sim::driver::egm::EgmLoop::new(&s, &mut plant, None, params, plant_sim::signals::Signals::detached()).unwrap();
    let (stats, es) = egm.run();
    let allocated = allocations() - a0;
    drop(egm);
    assert!(sensor.expect_exit(std::time::Duration::from_secs(10)).success(), "egm-controller: {}", sensor.stderr());
    assert_eq!(stats.ticks, n_ticks, "{stats:?}");
    assert!(es.accepted * 8 >= n_ticks / 4 * 7 && es.refused == 0, "the sensor answered every cycle: {es:?}");
    assert_eq!(plant.tick(), n_ticks);
    allocated
}

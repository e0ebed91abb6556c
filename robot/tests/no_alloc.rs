//! The hot-path algorithms must not touch the heap (the 1 kHz loops call them every tick).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use robot::{ik_seed_tool_down, tool_down_pose, Robot, Tool, Vec6};

struct Counting;

thread_local! {
    /// Allocations made by this thread only, so the test harness's own threads cannot interfere.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

// SAFETY: every method forwards to System, which upholds the GlobalAlloc contract.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwards the caller's GlobalAlloc contract to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn hot_paths_do_not_allocate() {
    let robot = Robot::irb2400_with_tool(Tool::default()).with_armature(Vec6::from_element(0.01)).with_viscous(Vec6::from_element(1.0));
    let q = Vec6::new(0.1, -1.2, 0.4, 0.2, 0.9, -0.3);
    let qd = Vec6::new(0.5, -0.3, 0.4, 1.0, -1.5, 2.0);
    let target = tool_down_pose(0.9, 0.0, 0.718);
    let seed = ik_seed_tool_down();
    let before = allocations();
    let mut sink = 0.0;
    for _ in 0..10 {
        let tau = robot.rnea(&q, &qd, &qd);
        sink += tau[0];
        sink += robot.mass_matrix(&q)[(1, 1)];
        sink += robot.forward_dynamics(&q, &qd, &tau)[2];
        sink += robot.gravity_torque(&q)[1] + robot.coriolis_times_qd(&q, &qd)[1];
        sink += robot.mass_matrix_and_bias(&q, &qd).1[0];
        sink += robot.jacobian_tcp(&q)[(0, 0)] + robot.jacobian_flange(&q)[(0, 0)];
        sink += robot.jdot_qdot_tcp(&q, &qd)[0];
        sink += robot.tcp_pose(&q).translation.vector.x + robot.flange_pose(&q).translation.vector.x;
        sink += robot.ik_tcp(&target, &seed).unwrap()[1];
    }
    let after = allocations();
    // The counter works: a Vec does allocate.
    let probe = allocations();
    std::hint::black_box(vec![1u8; 16]);
    assert_eq!(allocations(), probe + 1);
    assert!(sink.is_finite());
    assert_eq!(after - before, 0, "{} heap allocations on the hot paths", after - before);
}

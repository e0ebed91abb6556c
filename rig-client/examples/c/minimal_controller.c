/* minimal_controller.c: a complete rig controller in C on librig_client (rig-client, issue 27).
 *
 *     minimal_controller --rig NAME --scenario FILE.toml    (or: rig run --controller THIS_BINARY)
 *
 * Holds the arm at the first state's q: per joint tau = g(q) + KP (q0 - q) - KD qd, with g(q) from
 * the rig's model of the scenario (tool included). Answers every state of its tick; acknowledges a
 * reflex safe stop (RIG_CONTROLLER_STARTING); exits 0 on the plant's goodbye, 1 with one sentence
 * when the plant is gone or silent for 5 s. */
#include <stdio.h>
#include <string.h>

#include "rig_client.h"

/* Critically damped 10 Hz per joint on M_ii of the rig's start pose (kg m^2, 1 kg tool, rounded). */
static const double INERTIA[6] = {25.0, 47.0, 9.5, 0.057, 0.022, 0.0005};
#define OMEGA (2.0 * 3.141592653589793 * 10.0)
#define SILENCE_LIMIT 5 /* waits of 1 s without a state before giving up on a live plant */

static int fail(const char *what, int code) {
    const char *detail = rig_client_last_error();
    fprintf(stderr, "minimal_controller: error: %s: %s%s%s\n", what, rig_client_error_message(code), *detail ? ": " : "", detail);
    return 1;
}

int main(int argc, char **argv) {
    const char *rig = NULL, *scenario = NULL;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--rig") == 0) rig = argv[i + 1];
        else if (strcmp(argv[i], "--scenario") == 0) scenario = argv[i + 1];
    }
    if (!rig) {
        fprintf(stderr, "usage: %s --rig NAME [--scenario FILE.toml]\n", argv[0]);
        return 2;
    }
    RigModel *model = NULL;
    RigClient *client = NULL;
    int rc = rig_model_open(scenario, &model);
    if (rc != RIG_OK) return fail("robot model", rc);
    rc = rig_client_open(rig, "minimal-c-controller", scenario, 120.0, &client);
    if (rc != RIG_OK) return fail("open", rc);

    RigJointState st;
    RigWrench w;
    double q0[6], g[6], tau[6];
    int have_q0 = 0, silent = 0, exit_code = 1;
    for (;;) {
        rc = rig_client_wait(client, 1.0, &st, &w);
        if (rc == RIG_TIMEOUT) {
            if (++silent < SILENCE_LIMIT) continue;
            fprintf(stderr, "minimal_controller: error: rig %s: no state for %d s; exiting\n", rig, SILENCE_LIMIT);
            break;
        }
        silent = 0;
        if (rc == RIG_SHUTTING_DOWN) {
            exit_code = 0;
            break;
        }
        if (rc != RIG_OK && rc != RIG_SAFE_STOP_TO_ACKNOWLEDGE) {
            fail("wait", rc);
            break;
        }
        if (!have_q0) {
            memcpy(q0, st.q, sizeof q0);
            have_q0 = 1;
        }
        rig_model_gravity(model, st.q, g);
        for (int j = 0; j < 6; ++j)
            tau[j] = g[j] + INERTIA[j] * (OMEGA * OMEGA * (q0[j] - st.q[j]) - 2.0 * OMEGA * st.qd[j]);
        /* Status 1 (starting) acknowledges a latched reflex; otherwise 0 (active). */
        uint32_t status = rc == RIG_SAFE_STOP_TO_ACKNOWLEDGE ? RIG_CONTROLLER_STARTING : RIG_CONTROLLER_ACTIVE;
        rc = rig_client_publish(client, st.tick, status, tau, NULL);
        if (rc != RIG_OK) {
            fail("publish", rc);
            break;
        }
    }
    rig_client_close(client);
    rig_model_close(model);
    return exit_code;
}

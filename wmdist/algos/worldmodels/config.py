"""World Models configuration (defaults: Ha & Schmidhuber 2018 and the authors' code,
docs/reference.md#world-models)."""
from __future__ import annotations

from dataclasses import dataclass

from wmdist.algos.worldmodels.cmaes import MIN_POPSIZE
from wmdist.config.fields import MAX_PER_DECISION, param


@dataclass
class WorldModelsConfig:
    """The `algo` section for World Models: V (VAE), M (MDN-RNN), C (linear, CMA-ES).

    The learner trains in stages counted in its update calls: `vae_updates` steps of V on
    replayed frames, then `rnn_updates` steps of M on V's latents, then one CMA-ES generation
    per update call (the batch is not used) until `generations`."""

    # --- V ---------------------------------------------------------------------------------
    z_dim: int = param(32, "latent size of V (paper: 32)", ge=1)
    vae_depth: int = param(32, "channels of V's first conv layer, doubling per layer (paper: 32)", ge=1)
    kl_tolerance: float = param(0.5, "free bits: V's KL is not pushed below this x z_dim nats (authors' code: 0.5)", ge=0)
    vae_lr: float = param(1e-4, "Adam learning rate of V (authors' code: 1e-4)", gt=0)
    vae_frames: int = param(0, "frames per V update drawn from the batch's real steps (0 = all of them)", ge=0)
    vae_updates: int = param(1000, "stage 1: V updates before M trains", ge=0)
    # --- M ---------------------------------------------------------------------------------
    rnn_hidden: int = param(256, "LSTM units of M (paper: 256 for CarRacing, 512 for Doom)", ge=1)
    mixtures: int = param(5, "Gaussians per latent dimension in M's mixture (paper: 5)", ge=1)
    rnn_lr: float = param(1e-3, "Adam learning rate of M (authors' code: 1e-3)", gt=0)
    rnn_clip: float = param(1.0, "gradient norm clip of M (authors' code: 1.0)", ge=0)
    done_weight: float = param(1.0, "weight of M's done-head cross-entropy", ge=0)
    rnn_updates: int = param(1000, "stage 2: M updates before the controller search", ge=0)
    latent_cache: int = param(0, "stage 2: replayed windows whose V encodings the learner keeps, so a window "
                                 "replayed again is not encoded again (0 = encode every batch)", ge=0)
    temperature: float = param(1.0, "tau: M's sampling temperature in the dream (paper, Doom: 1.15)")
    # --- C and CMA-ES ----------------------------------------------------------------------
    controller_h: bool = param(True, "C reads M's hidden state: a = W [z, h] + b (paper). false: a = W z + b, the "
                                     "paper's 'V model only' ablation (CarRacing 632 +- 251 against 906 +- 21), "
                                     "with 99 instead of 867 weights for CMA-ES to search")
    popsize: int = param(64, f"CMA-ES population (paper: 64; cma needs >= {MIN_POPSIZE})",
                         le=MAX_PER_DECISION)
    rollouts: int = param(16, "rollouts per candidate, its fitness is their mean (paper: 16)", ge=1,
                          le=MAX_PER_DECISION)
    sigma0: float = param(0.1, "CMA-ES initial step size (authors' code: 0.1)", gt=0)
    generations: int = param(0, "stage 3: CMA-ES generations (0 = until the run ends)", ge=0)
    train_in: str = param("dream", "where candidates are scored: dream (M at temperature tau) or real (the env)",
                          choices=("dream", "real"))
    iterations: int = param(1, "rounds of controller search; between two rounds M is refitted for `refit_updates` "
                               "on replay, which by then holds the controller's own episodes (paper sec. 5, iterative "
                               "training: M learns what the controller's habits lead to)", ge=1)
    refit_updates: int = param(0, "M updates between two rounds of the search (with iterations > 1)", ge=0)
    reeval_every: int = param(0, "generations between re-evaluations of the search's mean and the generation's best "
                                 "candidate on `reeval_rollouts` rollouts; the best re-evaluated one is published "
                                 "(authors' code: the mean, every 25). 0 = publish the best-ever candidate", ge=0)
    reeval_rollouts: int = param(64, "rollouts of each re-evaluation (authors' code: 100 or more)", ge=1)
    dream_max_steps: int = param(2100, "cap of a dream rollout in steps (paper, Doom: 2100)", ge=1)
    real_envs: int = param(8, "envs an evaluation actor steps in lockstep for real rollouts (one batched V and M "
                               "call per step for all of them)", ge=1)
    real_max_steps: int = param(0, "cap of a real rollout in steps (0 = the env's own)", ge=0)
    real_patience: int = param(0, "a real rollout of the search also ends after this many steps in a row without a "
                                  "positive reward (0 = never). A CarRacing car off the track earns nothing until it "
                                  "finds the track again, so such frames mostly cost CPU (a departure: the paper plays "
                                  "every episode to its end)", ge=0)
    # --- the evaluation pool (role `wm_eval`) ----------------------------------------------
    eval_actors: int = param(1, "evaluation actors scoring candidates in parallel (0 = the learner scores dream rollouts itself)", ge=0)
    eval_actor_cpus: float = param(0.5, "Ray CPUs per evaluation actor", gt=0)
    eval_actor_resources: dict = param({}, "custom Ray resources per evaluation actor, e.g. {eval_node: 1} to place "
                                           "them on the cluster's tagged worker nodes")
    pool_max_retries: int = param(8, "times a share of candidates is sent again after its actor died", ge=0)
    # --- collecting ------------------------------------------------------------------------
    collect_noise: float = param(0.0, "collectors once C exists: Gaussian std on continuous actions, "
                                      "or the chance of a random discrete action", ge=0)
    collect_random: float = param(0.0, "once C exists, the chance that a collector plays an episode at random (as before "
                                       "C, with random_keep) instead of with C: with iterative training (iterations > 1) "
                                       "replay otherwise fills with C's episodes only, and the refitted M forgets random "
                                       "play (session 29: standing still then lived 2,015 dream steps, 148 real)",
                                   ge=0, le=1)
    random_keep: float = param(0.0, "random play (before C exists): probability that an env repeats its last random "
                                    "action, so runs last 1/(1 - p) steps and the random walk reaches states a fresh "
                                    "action per step rarely does (0 = the paper's random policy)", ge=0, lt=1)
    z_bank: int = param(1000, "initial latents (first frames' encodings) kept to start dreams from", ge=1)

    def validate(self) -> None:
        """One-line ValueError for what the ranges alone can't catch."""
        if self.popsize < MIN_POPSIZE:
            raise ValueError(f"algo.popsize must be >= {MIN_POPSIZE} (the CMA-ES minimum), got {self.popsize}")
        if not self.temperature > 0:
            raise ValueError(f"algo.temperature (tau) must be > 0, got {self.temperature}")
        if self.train_in == "dream" and self.rnn_updates == 0:
            raise ValueError("algo.train_in is dream but algo.rnn_updates is 0: a controller trained in the dream "
                             "needs a trained M")
        if self.iterations > 1 and (self.generations == 0 or self.refit_updates == 0):
            raise ValueError(f"algo.iterations is {self.iterations}: each round needs a fixed length "
                             f"(algo.generations > 0) and M a refit between rounds (algo.refit_updates > 0)")
        if self.train_in == "real" and self.eval_actors == 0:
            raise ValueError("algo.train_in is real: the real rollouts need evaluation actors (algo.eval_actors >= 1)")

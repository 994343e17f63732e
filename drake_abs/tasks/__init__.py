"""Concrete systems the experiments use: the point mass and the translating box as linear
complementarity systems, the 12-state quadcopter of the differentiable-MPC experiments, and
gymnasium's Hopper-v5, HalfCheetah-v5, Walker2d-v5 and Ant-v5 on our plant (``locomotion``: v5
rewards, observations, action range and reset noise; ``ant``: the Ant's reward, observation and
contact wrenches; ``free_body``: MuJoCo's coordinates of a free body; ``adapters``: action scaling
and observation policies; ``gym_env``: a ``gymnasium.Env`` of any task; ``sb3_vec_env``: n copies
of a task as a stable-baselines3 ``VecEnv`` stepped in one batch, for ``sb3_baselines``).

Drake-free to import; ``locomotion.locomotion_task`` builds a scene's stepper
(:mod:`drake_abs.multibody`, Drake) when called, and ``gym_env`` needs gymnasium.
"""

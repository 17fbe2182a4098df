"""IPOPT's options as data: which ones a design file may set, and what each allows.

``[solve] ipopt_options`` of a design file (and ``SolveOptions(ipopt_options=...)``) is
checked against :data:`OPTIONS` by :func:`check_ipopt_options`: a table of every option of
IPOPT 3.14 (the version CasADi 3.8 ships) with its type and range, taken from IPOPT's own
documentation (its option ``print_options_documentation``). Nothing is built to check them,
and no solver sees an option before the solve.

A file from someone else must not make IPOPT open a file or load a library, so the options
that name one (:data:`FILE_OPTIONS`) and the choices that load a shared library at run time
(:data:`LOADING_CHOICES`) are refused unless the caller trusts the file (``--trust``,
``trust=True``). Every solver the package builds also sets ``option_file_name`` to "" (see
:data:`NO_OPTION_FILE`): otherwise IPOPT reads an ``ipopt.opt`` from the working folder, which
may be a folder someone else sent, and that file can name files and libraries too.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from typing import Any

from .errors import InputError
from .files import Key, check_value, describe_value, key_name

#: Options that name a file or a library, and what IPOPT does with it.
FILE_OPTIONS = {
    "output_file": "writes (and first empties) the file it names",
    "option_file_name": "reads the file it names and prints its options",
    "hsllib": "loads the shared library it names, running its code",
    "pardisolib": "loads the shared library it names, running its code",
}
#: Values of choice options that load a shared library at run time (from ``hsllib``,
#: ``pardisolib`` or the system's library path).
LOADING_CHOICES = {
    "linear_solver": ("ma27", "ma57", "ma77", "ma86", "ma97", "pardiso", "custom"),
    "linear_system_scaling": ("mc19",),
}
#: Set in every IPOPT solver the package builds: read no options file.
NO_OPTION_FILE = {"ipopt.option_file_name": ""}

_YES_NO = Key("choice", choices=("yes", "no"))


def _number(low: float | None, high: float | None, low_open: bool = False,
            high_open: bool = False) -> Key:
    return Key("number", low=low, high=high, low_open=low_open, high_open=high_open)


#: IPOPT's integers are C ints.
INT_MAX = 2**31 - 1


def _whole(low: int | None, high: int | None, low_open: bool = False,
           high_open: bool = False) -> Key:
    return Key("whole", low=-INT_MAX - 1 if low is None else low,
               high=INT_MAX if high is None else high, low_open=low_open,
               high_open=high_open and high is not None)


def _choice(*choices: str) -> Key:
    return Key("choice", choices=choices)


#: Every IPOPT option but :data:`FILE_OPTIONS`, with what it allows (IPOPT's bounds; its
#: integers as whole numbers, its strings as their listed values).
OPTIONS: dict[str, Key] = {
    "tol": _number(0, None, low_open=True),
    "s_max": _number(0, None, low_open=True),
    "max_iter": _whole(0, None),
    "max_wall_time": _number(0, None, low_open=True),
    "max_cpu_time": _number(0, None, low_open=True),
    "dual_inf_tol": _number(0, None, low_open=True),
    "constr_viol_tol": _number(0, None, low_open=True),
    "compl_inf_tol": _number(0, None, low_open=True),
    "acceptable_tol": _number(0, None, low_open=True),
    "acceptable_iter": _whole(0, None),
    "acceptable_dual_inf_tol": _number(0, None, low_open=True),
    "acceptable_constr_viol_tol": _number(0, None, low_open=True),
    "acceptable_compl_inf_tol": _number(0, None, low_open=True),
    "acceptable_obj_change_tol": _number(0, None),
    "diverging_iterates_tol": _number(0, None, low_open=True),
    "mu_target": _number(0, None),
    "print_level": _whole(0, 12),
    "file_print_level": _whole(0, 12),
    "file_append": _YES_NO,
    "print_user_options": _YES_NO,
    "print_options_documentation": _YES_NO,
    "print_timing_statistics": _YES_NO,
    "print_options_mode": _choice('text', 'latex', 'doxygen'),
    "print_advanced_options": _YES_NO,
    "print_info_string": _YES_NO,
    "inf_pr_output": _choice('internal', 'original'),
    "print_frequency_iter": _whole(1, None),
    "print_frequency_time": _number(0, None),
    "nlp_lower_bound_inf": _number(None, None),
    "nlp_upper_bound_inf": _number(None, None),
    "fixed_variable_treatment": _choice('make_parameter', 'make_parameter_nodual',
                                        'make_constraint', 'relax_bounds'),
    "dependency_detector": _choice('none', 'mumps'),
    "dependency_detection_with_rhs": _YES_NO,
    "num_linear_variables": _whole(0, None),
    "jacobian_approximation": _choice('exact', 'finite-difference-values'),
    "gradient_approximation": _choice('exact', 'finite-difference-values'),
    "findiff_perturbation": _number(0, None, low_open=True),
    "kappa_d": _number(0, None),
    "bound_relax_factor": _number(0, None),
    "honor_original_bounds": _YES_NO,
    "check_derivatives_for_naninf": _YES_NO,
    "grad_f_constant": _YES_NO,
    "jac_c_constant": _YES_NO,
    "jac_d_constant": _YES_NO,
    "hessian_constant": _YES_NO,
    "nlp_scaling_method": _choice('none', 'user-scaling', 'gradient-based', 'equilibration-based'),
    "obj_scaling_factor": _number(None, None),
    "nlp_scaling_max_gradient": _number(0, None, low_open=True),
    "nlp_scaling_obj_target_gradient": _number(0, None),
    "nlp_scaling_constr_target_gradient": _number(0, None),
    "nlp_scaling_min_value": _number(0, None),
    "bound_push": _number(0, None, low_open=True),
    "bound_frac": _number(0, 0.5, low_open=True),
    "slack_bound_push": _number(0, None, low_open=True),
    "slack_bound_frac": _number(0, 0.5, low_open=True),
    "constr_mult_init_max": _number(0, None),
    "bound_mult_init_val": _number(0, None, low_open=True),
    "bound_mult_init_method": _choice('constant', 'mu-based'),
    "least_square_init_primal": _YES_NO,
    "least_square_init_duals": _YES_NO,
    "warm_start_init_point": _YES_NO,
    "warm_start_same_structure": _YES_NO,
    "warm_start_bound_push": _number(0, None, low_open=True),
    "warm_start_bound_frac": _number(0, 0.5, low_open=True),
    "warm_start_slack_bound_push": _number(0, None, low_open=True),
    "warm_start_slack_bound_frac": _number(0, 0.5, low_open=True),
    "warm_start_mult_bound_push": _number(0, None, low_open=True),
    "warm_start_mult_init_max": _number(None, None),
    "warm_start_entire_iterate": _YES_NO,
    "warm_start_target_mu": _number(None, None),
    "replace_bounds": _YES_NO,
    "skip_finalize_solution_call": _YES_NO,
    "timing_statistics": _YES_NO,
    "mu_max_fact": _number(0, None, low_open=True),
    "mu_max": _number(0, None, low_open=True),
    "mu_min": _number(0, None, low_open=True),
    "adaptive_mu_globalization": _choice('kkt-error', 'obj-constr-filter', 'never-monotone-mode'),
    "adaptive_mu_kkterror_red_iters": _whole(0, None),
    "adaptive_mu_kkterror_red_fact": _number(0, 1, low_open=True, high_open=True),
    "filter_margin_fact": _number(0, 1, low_open=True, high_open=True),
    "filter_max_margin": _number(0, None, low_open=True),
    "adaptive_mu_restore_previous_iterate": _YES_NO,
    "adaptive_mu_monotone_init_factor": _number(0, None, low_open=True),
    "adaptive_mu_kkt_norm_type": _choice('1-norm', '2-norm-squared', 'max-norm', '2-norm'),
    "mu_strategy": _choice('monotone', 'adaptive'),
    "mu_oracle": _choice('probing', 'loqo', 'quality-function'),
    "fixed_mu_oracle": _choice('probing', 'loqo', 'quality-function', 'average_compl'),
    "mu_init": _number(0, None, low_open=True),
    "barrier_tol_factor": _number(0, None, low_open=True),
    "mu_linear_decrease_factor": _number(0, 1, low_open=True, high_open=True),
    "mu_superlinear_decrease_power": _number(1, 2, low_open=True, high_open=True),
    "mu_allow_fast_monotone_decrease": _YES_NO,
    "tau_min": _number(0, 1, low_open=True, high_open=True),
    "sigma_max": _number(0, None, low_open=True),
    "sigma_min": _number(0, None),
    "quality_function_norm_type": _choice('1-norm', '2-norm-squared', 'max-norm', '2-norm'),
    "quality_function_centrality": _choice('none', 'log', 'reciprocal', 'cubed-reciprocal'),
    "quality_function_balancing_term": _choice('none', 'cubic'),
    "quality_function_max_section_steps": _whole(0, None),
    "quality_function_section_sigma_tol": _number(0, 1, high_open=True),
    "quality_function_section_qf_tol": _number(0, 1, high_open=True),
    "line_search_method": _choice('filter', 'cg-penalty', 'penalty'),
    "alpha_red_factor": _number(0, 1, low_open=True, high_open=True),
    "accept_every_trial_step": _YES_NO,
    "accept_after_max_steps": _whole(-1, None),
    "alpha_for_y": _choice('primal', 'bound-mult', 'min', 'max', 'full', 'min-dual-infeas',
                           'safer-min-dual-infeas', 'primal-and-full', 'dual-and-full', 'acceptor'),
    "alpha_for_y_tol": _number(0, None),
    "tiny_step_tol": _number(0, None),
    "tiny_step_y_tol": _number(0, None),
    "watchdog_shortened_iter_trigger": _whole(0, None),
    "watchdog_trial_iter_max": _whole(1, None),
    "theta_max_fact": _number(0, None, low_open=True),
    "theta_min_fact": _number(0, None, low_open=True),
    "eta_phi": _number(0, 0.5, low_open=True, high_open=True),
    "delta": _number(0, None, low_open=True),
    "s_phi": _number(1, None, low_open=True),
    "s_theta": _number(1, None, low_open=True),
    "gamma_phi": _number(0, 1, low_open=True, high_open=True),
    "gamma_theta": _number(0, 1, low_open=True, high_open=True),
    "alpha_min_frac": _number(0, 1, low_open=True, high_open=True),
    "max_soc": _whole(0, None),
    "kappa_soc": _number(0, None, low_open=True),
    "obj_max_inc": _number(1, None, low_open=True),
    "max_filter_resets": _whole(0, None),
    "filter_reset_trigger": _whole(1, None),
    "corrector_type": _choice('none', 'affine', 'primal-dual'),
    "skip_corr_if_neg_curv": _YES_NO,
    "skip_corr_in_monotone_mode": _YES_NO,
    "corrector_compl_avrg_red_fact": _number(0, None, low_open=True),
    "soc_method": _whole(0, 1),
    "nu_init": _number(0, None, low_open=True),
    "nu_inc": _number(0, None, low_open=True),
    "rho": _number(0, 1, low_open=True, high_open=True),
    "kappa_sigma": _number(0, None, low_open=True),
    "recalc_y": _YES_NO,
    "recalc_y_feas_tol": _number(0, None, low_open=True),
    "slack_move": _number(0, None),
    "constraint_violation_norm_type": _choice('1-norm', '2-norm', 'max-norm'),
    "linear_solver": _choice('ma27', 'ma57', 'ma77', 'ma86', 'ma97', 'pardiso', 'spral', 'mumps',
                             'custom'),
    "linear_system_scaling": _choice('none', 'mc19', 'slack-based'),
    "linear_scaling_on_demand": _YES_NO,
    "mehrotra_algorithm": _YES_NO,
    "fast_step_computation": _YES_NO,
    "min_refinement_steps": _whole(0, None),
    "max_refinement_steps": _whole(0, None),
    "residual_ratio_max": _number(0, None, low_open=True),
    "residual_ratio_singular": _number(0, None, low_open=True),
    "residual_improvement_factor": _number(0, None, low_open=True),
    "neg_curv_test_tol": _number(0, None),
    "neg_curv_test_reg": _YES_NO,
    "max_hessian_perturbation": _number(0, None, low_open=True),
    "min_hessian_perturbation": _number(0, None),
    "perturb_inc_fact_first": _number(1, None, low_open=True),
    "perturb_inc_fact": _number(1, None, low_open=True),
    "perturb_dec_fact": _number(0, 1, low_open=True, high_open=True),
    "first_hessian_perturbation": _number(0, None, low_open=True),
    "jacobian_regularization_value": _number(0, None),
    "jacobian_regularization_exponent": _number(0, None),
    "perturb_always_cd": _YES_NO,
    "expect_infeasible_problem": _YES_NO,
    "expect_infeasible_problem_ctol": _number(0, None),
    "expect_infeasible_problem_ytol": _number(0, None, low_open=True),
    "start_with_resto": _YES_NO,
    "soft_resto_pderror_reduction_factor": _number(0, None),
    "max_soft_resto_iters": _whole(0, None),
    "required_infeasibility_reduction": _number(0, 1, high_open=True),
    "max_resto_iter": _whole(0, None),
    "evaluate_orig_obj_at_resto_trial": _YES_NO,
    "resto_penalty_parameter": _number(0, None, low_open=True),
    "resto_proximity_weight": _number(0, None),
    "bound_mult_reset_threshold": _number(0, None),
    "constr_mult_reset_threshold": _number(0, None),
    "resto_failure_feasibility_threshold": _number(0, None),
    "limited_memory_aug_solver": _choice('sherman-morrison', 'extended'),
    "limited_memory_max_history": _whole(0, None),
    "limited_memory_update_type": _choice('bfgs', 'sr1'),
    "limited_memory_initialization": _choice('scalar1', 'scalar2', 'scalar3', 'scalar4',
                                             'constant'),
    "limited_memory_init_val": _number(0, None, low_open=True),
    "limited_memory_init_val_max": _number(0, None, low_open=True),
    "limited_memory_init_val_min": _number(0, None, low_open=True),
    "limited_memory_max_skipping": _whole(1, None),
    "limited_memory_special_for_resto": _YES_NO,
    "hessian_approximation": _choice('exact', 'limited-memory'),
    "hessian_approximation_space": _choice('nonlinear-variables', 'all-variables'),
    "derivative_test": _choice('none', 'first-order', 'second-order', 'only-second-order'),
    "derivative_test_first_index": _whole(-2, None),
    "derivative_test_perturbation": _number(0, None, low_open=True),
    "derivative_test_tol": _number(0, None, low_open=True),
    "derivative_test_print_all": _YES_NO,
    "point_perturbation_radius": _number(0, None),
    "ma27_print_level": _whole(0, 4),
    "ma27_pivtol": _number(0, 1, low_open=True, high_open=True),
    "ma27_pivtolmax": _number(0, 1, low_open=True, high_open=True),
    "ma27_liw_init_factor": _number(1, None),
    "ma27_la_init_factor": _number(1, None),
    "ma27_meminc_factor": _number(1, None),
    "ma27_skip_inertia_check": _YES_NO,
    "ma27_ignore_singularity": _YES_NO,
    "ma57_print_level": _whole(0, None),
    "ma57_pivtol": _number(0, 1, low_open=True, high_open=True),
    "ma57_pivtolmax": _number(0, 1, low_open=True, high_open=True),
    "ma57_pre_alloc": _number(1, None),
    "ma57_pivot_order": _whole(0, 5),
    "ma57_automatic_scaling": _YES_NO,
    "ma57_block_size": _whole(1, None),
    "ma57_node_amalgamation": _whole(1, None),
    "ma57_small_pivot_flag": _whole(0, 1),
    "ma77_print_level": _whole(None, None),
    "ma77_buffer_lpage": _whole(1, None),
    "ma77_buffer_npage": _whole(1, None),
    "ma77_file_size": _whole(1, None),
    "ma77_maxstore": _whole(0, None),
    "ma77_nemin": _whole(1, None),
    "ma77_small": _number(0, None),
    "ma77_static": _number(0, None),
    "ma77_u": _number(0, 0.5),
    "ma77_umax": _number(0, 0.5),
    "ma77_order": _choice('amd', 'metis'),
    "ma86_print_level": _whole(None, None),
    "ma86_nemin": _whole(1, None),
    "ma86_small": _number(0, None),
    "ma86_static": _number(0, None),
    "ma86_u": _number(0, 0.5),
    "ma86_umax": _number(0, 0.5),
    "ma86_scaling": _choice('none', 'mc64', 'mc77'),
    "ma86_order": _choice('auto', 'amd', 'metis'),
    "ma97_print_level": _whole(None, None),
    "ma97_nemin": _whole(1, None),
    "ma97_small": _number(0, None),
    "ma97_u": _number(0, 0.5),
    "ma97_umax": _number(0, 0.5),
    "ma97_scaling": _choice('none', 'mc30', 'mc64', 'mc77', 'dynamic'),
    "ma97_scaling1": _choice('none', 'mc30', 'mc64', 'mc77'),
    "ma97_switch1": _choice('never', 'at_start', 'at_start_reuse', 'on_demand', 'on_demand_reuse',
                            'high_delay', 'high_delay_reuse', 'od_hd', 'od_hd_reuse'),
    "ma97_scaling2": _choice('none', 'mc30', 'mc64', 'mc77'),
    "ma97_switch2": _choice('never', 'at_start', 'at_start_reuse', 'on_demand', 'on_demand_reuse',
                            'high_delay', 'high_delay_reuse', 'od_hd', 'od_hd_reuse'),
    "ma97_scaling3": _choice('none', 'mc30', 'mc64', 'mc77'),
    "ma97_switch3": _choice('never', 'at_start', 'at_start_reuse', 'on_demand', 'on_demand_reuse',
                            'high_delay', 'high_delay_reuse', 'od_hd', 'od_hd_reuse'),
    "ma97_order": _choice('auto', 'best', 'amd', 'metis', 'matched-auto', 'matched-metis',
                          'matched-amd'),
    "ma97_solve_blas3": _YES_NO,
    "pardiso_matching_strategy": _choice('complete', 'complete+2x2', 'constraints'),
    "pardiso_redo_symbolic_fact_only_if_inertia_wrong": _YES_NO,
    "pardiso_repeated_perturbation_means_singular": _YES_NO,
    "pardiso_msglvl": _whole(0, None),
    "pardiso_skip_inertia_check": _YES_NO,
    "pardiso_max_iterative_refinement_steps": _whole(None, None),
    "pardiso_order": _choice('amd', 'one', 'metis', 'pmetis', 'four', 'five'),
    "pardiso_max_iter": _whole(1, None),
    "pardiso_iter_relative_tol": _number(0, 1, low_open=True, high_open=True),
    "pardiso_iter_coarse_size": _whole(1, None),
    "pardiso_iter_max_levels": _whole(1, None),
    "pardiso_iter_dropping_factor": _number(0, 1, low_open=True, high_open=True),
    "pardiso_iter_dropping_schur": _number(0, 1, low_open=True, high_open=True),
    "pardiso_iter_max_row_fill": _whole(1, None),
    "pardiso_iter_inverse_norm_factor": _number(1, None, low_open=True),
    "pardiso_iterative": _YES_NO,
    "pardiso_max_droptol_corrections": _whole(1, None),
    "spral_cpu_block_size": _whole(1, None),
    "spral_gpu_perf_coeff": _number(0, None, low_open=True),
    "spral_ignore_numa": _YES_NO,
    "spral_max_load_inbalance": _number(1, None, low_open=True),
    "spral_min_gpu_work": _number(0, None),
    "spral_nemin": _whole(1, None),
    "spral_order": _choice('metis', 'matching'),
    "spral_pivot_method": _choice('aggressive', 'block', 'threshold'),
    "spral_print_level": _whole(None, None),
    "spral_scaling": _choice('none', 'mc64', 'auction', 'matching', 'ruiz', 'dynamic'),
    "spral_scaling_1": _choice('none', 'mc64', 'auction', 'matching', 'ruiz'),
    "spral_scaling_2": _choice('none', 'mc64', 'auction', 'matching', 'ruiz'),
    "spral_scaling_3": _choice('none', 'mc64', 'auction', 'matching', 'ruiz'),
    "spral_switch_1": _choice('never', 'at_start', 'at_start_reuse', 'on_demand',
                              'on_demand_reuse', 'high_delay', 'high_delay_reuse', 'od_hd',
                              'od_hd_reuse'),
    "spral_switch_2": _choice('never', 'at_start', 'at_start_reuse', 'on_demand',
                              'on_demand_reuse', 'high_delay', 'high_delay_reuse', 'od_hd',
                              'od_hd_reuse'),
    "spral_switch_3": _choice('never', 'at_start', 'at_start_reuse', 'on_demand',
                              'on_demand_reuse', 'high_delay', 'high_delay_reuse', 'od_hd',
                              'od_hd_reuse'),
    "spral_small": _number(0, None, low_open=True),
    "spral_small_subtree_threshold": _number(0, None, low_open=True),
    "spral_u": _number(0, 0.5, low_open=True),
    "spral_umax": _number(0, 0.5, low_open=True),
    "spral_use_gpu": _YES_NO,
    "mumps_print_level": _whole(0, None),
    "mumps_pivtol": _number(0, 1),
    "mumps_pivtolmax": _number(0, 1),
    "mumps_mem_percent": _whole(0, None),
    "mumps_permuting_scaling": _whole(0, 7),
    "mumps_pivot_order": _whole(0, 7),
    "mumps_scaling": _whole(-2, 77),
    "mumps_dep_tol": _number(None, None),
}


def check_ipopt_options(options: Any, reserved: Mapping[str, str] = {},
                        trust: bool = False) -> dict[str, str | int | float]:
    """``options`` (IPOPT options by name, an "ipopt." prefix allowed) checked against
    :data:`OPTIONS` and converted; one :class:`InputError` line naming the option and what
    it allows otherwise.

    ``reserved`` maps options that another setting owns to that setting's name (refused
    here, e.g. ``max_iter`` -> SolveOptions' ``max_iter``). Without ``trust``, the options
    of :data:`FILE_OPTIONS` and the choices of :data:`LOADING_CHOICES` are refused; with
    it, a file option takes any string.
    """
    where = "[solve] ipopt_options"
    if not isinstance(options, Mapping):
        raise InputError(f"{where} must be a table of IPOPT options, got "
                         f"{describe_value(options)}")
    out: dict[str, str | int | float] = {}
    for key, value in options.items():
        if not isinstance(key, str):
            raise InputError(f"{where} takes option names as keys, got {describe_value(key)}")
        name = key.removeprefix("ipopt.")
        if name in reserved:
            raise InputError(f"{where}: set {name} through {reserved[name]}, not "
                             "ipopt_options")
        if name in FILE_OPTIONS:
            if not trust:
                raise InputError(
                    f"{key_name(where, name)} names a file or library (IPOPT "
                    f"{FILE_OPTIONS[name]}); refused in a file from others: pass --trust "
                    "(trust=True in the API) if you wrote it yourself")
            out[name] = check_value(value, Key("string"), key_name(where, name))
            continue
        if name not in OPTIONS:
            close = difflib.get_close_matches(name, OPTIONS, n=1)
            raise InputError(f"{key_name(where, name)} is not an option of IPOPT 3.14"
                             + (f"; did you mean {close[0]}?" if close else
                                " (IPOPT's documentation lists its options)"))
        value = check_value(value, OPTIONS[name], key_name(where, name))
        if value in LOADING_CHOICES.get(name, ()) and not trust:
            raise InputError(
                f"{key_name(where, name)} = {value!r} makes IPOPT load a shared library at "
                "run time; refused in a file from others: pass --trust (trust=True in the "
                "API) if you installed it yourself")
        out[name] = value
    return out

//! The critic's first-order gradient penalty without `CANDLE_GRAD_DO_NOT_DETACH`: this file never
//! sets it, so candle detaches every gradient, as in a program that does not ask for second
//! order; the penalty's gradient must still match finite differences.

mod common;
use common::penalty::{
    first_order_penalty, penalty_gradient_matches_finite_differences, SMALL_CRITIC, WIDE_CRITIC,
};
use patch_gan::PatchDiscriminatorConfig;

#[test]
fn the_variable_is_not_set() {
    assert!(std::env::var_os("CANDLE_GRAD_DO_NOT_DETACH").is_none());
}

#[test]
fn first_order_penalty_gradient_matches_finite_differences() {
    penalty_gradient_matches_finite_differences::<2>(SMALL_CRITIC, 1, first_order_penalty);
}

#[test]
fn first_order_penalty_of_a_volume_critic_matches_finite_differences() {
    // Two channels of 6^3 volumes: every weight and bias of both layers.
    let cfg = PatchDiscriminatorConfig {
        channels: 2,
        ..SMALL_CRITIC
    };
    penalty_gradient_matches_finite_differences::<3>(cfg, 1, first_order_penalty);
}

#[test]
fn first_order_penalty_gradient_matches_finite_differences_through_winograd() {
    // Every 97th weight, as the double backward's test.
    penalty_gradient_matches_finite_differences::<2>(WIDE_CRITIC, 97, first_order_penalty);
}

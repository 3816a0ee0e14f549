; Carry-or-push: the cube must end up in a box next to its table. The robot can
; carry it there (grasp, drive, place) or push it off the table edge into the
; box. Same mapping convention as pick_place_domain.pddl: arguments of type
; `region` are the template's symbolic parameters, the rest are bookkeeping.
; `road` is a static one-way drive graph, so no plan can loop or take detours and
; the planner's top-k list holds exactly the two skeletons.
(define (domain carry-or-push)
  (:requirements :strips :typing)
  (:types
    region site cube - object
    base_region grasp_region place_region push_region - region)
  (:predicates
    (robot-at ?p - site)
    (road ?from - site ?to - site)
    (base-near ?r - base_region ?p - site)
    (hand-empty)
    (holding ?c - cube)
    (cube-at ?c - cube ?p - site)
    (grasps ?g - grasp_region ?c - cube)
    (place-on ?r - place_region ?p - site)
    ; pushing ?c at a point of ?r from base site ?b moves it from ?p1 to ?p2
    (pushes ?r - push_region ?c - cube ?b - site ?p1 - site ?p2 - site))

  (:action move_to
    :parameters (?r - base_region ?from - site ?to - site)
    :precondition (and (robot-at ?from) (road ?from ?to) (base-near ?r ?to))
    :effect (and (not (robot-at ?from)) (robot-at ?to)))

  (:action grasp
    :parameters (?g - grasp_region ?c - cube ?p - site)
    :precondition (and (hand-empty) (robot-at ?p) (cube-at ?c ?p) (grasps ?g ?c))
    :effect (and (not (hand-empty)) (not (cube-at ?c ?p)) (holding ?c)))

  (:action place
    :parameters (?r - place_region ?c - cube ?p - site)
    :precondition (and (holding ?c) (robot-at ?p) (place-on ?r ?p))
    :effect (and (not (holding ?c)) (hand-empty) (cube-at ?c ?p)))

  (:action push
    :parameters (?r - push_region ?c - cube ?b - site ?p1 - site ?p2 - site)
    :precondition (and (hand-empty) (robot-at ?b) (cube-at ?c ?p1) (pushes ?r ?c ?b ?p1 ?p2))
    :effect (and (not (cube-at ?c ?p1)) (cube-at ?c ?p2))))

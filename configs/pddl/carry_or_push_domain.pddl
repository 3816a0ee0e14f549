; Carry-or-push (scene=carry_or_push): the cube resting on top of an upright stick must end up
; in an open box on the floor. The robot can carry it (grasp it off the stick top, place it into
; the box) or push the stick over towards the box so that the cube falls in.
; Mapping convention (realize/pddl.py): arguments of type `region` (and its subtypes) are the
; template's symbolic parameters, mapped by name to the task's params; the rest (where the base
; parks, where the cube is) is bookkeeping and is dropped.
; A `site` is where the base parks, a `spot` where the cube can be; `reach` says which spots the
; arm reaches from which site. `road` is a static one-way drive graph from the start, so no plan
; loops and the planner's top-k list holds exactly the problem's skeletons.
(define (domain carry-or-push)
  (:requirements :strips :typing)
  (:types
    region site spot cube - object
    base_region grasp_region place_region push_region - region)
  (:predicates
    (robot-at ?s - site)
    (road ?from - site ?to - site)
    (base-near ?r - base_region ?s - site)
    (reach ?s - site ?p - spot)
    (hand-empty)
    (holding ?c - cube)
    (cube-at ?c - cube ?p - spot)
    (grasps ?g - grasp_region ?p - spot)
    (place-on ?r - place_region ?p - spot)
    ; pushing at a point of ?r from site ?b moves what rests at ?p1 to ?p2
    (pushes ?r - push_region ?b - site ?p1 - spot ?p2 - spot))

  (:action move_to
    :parameters (?r - base_region ?from - site ?to - site)
    :precondition (and (robot-at ?from) (road ?from ?to) (base-near ?r ?to))
    :effect (and (not (robot-at ?from)) (robot-at ?to)))

  (:action grasp
    :parameters (?g - grasp_region ?c - cube ?s - site ?p - spot)
    :precondition (and (hand-empty) (robot-at ?s) (reach ?s ?p) (cube-at ?c ?p) (grasps ?g ?p))
    :effect (and (not (hand-empty)) (not (cube-at ?c ?p)) (holding ?c)))

  (:action place
    :parameters (?r - place_region ?c - cube ?s - site ?p - spot)
    :precondition (and (holding ?c) (robot-at ?s) (reach ?s ?p) (place-on ?r ?p))
    :effect (and (not (holding ?c)) (hand-empty) (cube-at ?c ?p)))

  (:action push
    :parameters (?r - push_region ?c - cube ?b - site ?p1 - spot ?p2 - spot)
    :precondition (and (hand-empty) (robot-at ?b) (cube-at ?c ?p1) (pushes ?r ?b ?p1 ?p2))
    :effect (and (not (cube-at ?c ?p1)) (cube-at ?c ?p2))))

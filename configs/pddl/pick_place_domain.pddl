; Pick-and-place with a mobile manipulator (seed paper, Sec. IV).
;
; Each action is one of realize's action templates. Objects of type `region`
; (and its subtypes) are the task's symbolic parameters; every other argument
; (sites, the cube) is symbolic bookkeeping that realize drops when it maps a
; PDDL action to a template call.
(define (domain pick-place)
  (:requirements :strips :typing)
  (:types
    region site cube - object
    base_region grasp_region place_region - region)
  (:predicates
    (robot-at ?p - site)                          ; the base is parked at a site
    (base-near ?r - base_region ?p - site)        ; parking in ?r puts the base at ?p
    (hand-empty)
    (holding ?c - cube)
    (cube-at ?c - cube ?p - site)
    (grasps ?g - grasp_region ?c - cube)           ; ?g holds grasp poses of ?c
    (place-on ?r - place_region ?p - site))       ; ?r holds place poses at ?p

  (:action move_to
    :parameters (?r - base_region ?from - site ?to - site)
    :precondition (and (robot-at ?from) (base-near ?r ?to))
    :effect (and (not (robot-at ?from)) (robot-at ?to)))

  (:action grasp
    :parameters (?g - grasp_region ?c - cube ?p - site)
    :precondition (and (hand-empty) (robot-at ?p) (cube-at ?c ?p) (grasps ?g ?c))
    :effect (and (not (hand-empty)) (not (cube-at ?c ?p)) (holding ?c)))

  (:action place
    :parameters (?r - place_region ?c - cube ?p - site)
    :precondition (and (holding ?c) (robot-at ?p) (place-on ?r ?p))
    :effect (and (not (holding ?c)) (hand-empty) (cube-at ?c ?p))))
